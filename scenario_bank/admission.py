"""What a script passes to enter a bank: an optional upgrade from Scenic 2, then the safety check and a
compile, sample and short run in the sandbox (:mod:`scenario_bank.sandbox`); a refusal is a
:class:`~scenario_bank.errors.ScenarioRejectedError` naming the problem.
"""

from __future__ import annotations

from typing import Any, Dict, Optional, Tuple, Union

from scenario_bank.errors import BankOptionError, ScenarioRejectedError
from scenario_bank.records import Provenance
from scenario_bank.safety import UnsafeScenarioError
from scenario_bank.sandbox import SandboxError, verify_script
from scenario_bank.scenic2 import looks_like_scenic2, upgrade_scenic2

__all__ = ["ON_DUPLICATE", "ON_DUPLICATE_OF", "check_on_duplicate", "verify", "upgrade_if_asked",
           "verify_or_name_scenic2"]

ON_DUPLICATE = {
    "error": "refuse it (DuplicateScenarioError naming the entry it duplicates); an import then imports nothing",
    "merge": "merge it into the entry it duplicates or nearly duplicates: its provenance is appended to that "
             "entry's source.merged",
    "skip": "leave it out and go on with the other entries: an archive entry the bank already holds",
}
"""What may happen to a script the bank already holds (``on_duplicate``), one set for every way into a bank."""
ON_DUPLICATE_OF = {"add": ("error", "merge"), "import": ("skip", "error")}
"""The :data:`ON_DUPLICATE` values each way into a bank takes: ``Bank.add`` (one script: refuse or merge) and
``Bank.import_archive`` (several entries, all or nothing: refuse or skip the ones already held)."""


def check_on_duplicate(value: str, operation: str) -> str:
    """``value`` when ``operation`` (a key of :data:`ON_DUPLICATE_OF`) takes it, else a :class:`BankOptionError`
    naming the values it takes."""
    allowed = ON_DUPLICATE_OF[operation]
    if value not in allowed:
        other = [op for op, values in ON_DUPLICATE_OF.items() if value in values]
        hint = f" ({value!r} applies to {other[0]})" if other else ""
        raise BankOptionError(f"on_duplicate must be one of {', '.join(repr(o) for o in allowed)}, not {value!r}"
                              f"{hint}")
    return value


def verify(script: str, label: str) -> None:
    """Safety-check, compile, sample and run ``script`` once in the sandbox; raise
    :class:`ScenarioRejectedError` naming the problem. Passes are cached by content and code version."""
    try:
        verify_script(script, name=label)
    except UnsafeScenarioError as error:
        raise ScenarioRejectedError(f"not added: {error}", "safety", findings=error.findings) from None
    except SandboxError as error:
        raise ScenarioRejectedError(f"not added: {error}", error.stage, limit=error.limit) from None


def upgrade_if_asked(script: str, provenance: Optional[Provenance],
                     upgrade: bool) -> Tuple[str, Union[None, Provenance, Dict[str, Any]]]:
    """``script`` upgraded from Scenic 2 when ``upgrade`` is asked, its rewrites and notes added to ``provenance``
    (its JSON object comes back with them; ``provenance`` itself when nothing was upgraded)."""
    if not upgrade or not isinstance(script, str):
        return script, provenance

    result = upgrade_scenic2(script)
    if not result.changed:
        return script, provenance
    upgraded = provenance.to_dict() if provenance is not None else {}
    upgraded["scenic2_rewrites"] = [str(r) for r in result.rewrites]
    upgraded["scenic2_notes"] = list(result.notes)
    return result.source, upgraded


def verify_or_name_scenic2(script: str, label: str, upgraded: bool) -> None:
    """:func:`verify`; a refused script in Scenic 2 syntax (not upgraded) gets an error naming the construct."""
    try:
        verify(script, label)
    except ScenarioRejectedError as error:
        if not upgraded:
            if looks_like_scenic2(script, str(error)):
                first = upgrade_scenic2(script, keep_scenic2_meaning=False).rewrites[0]  # refused in 3
                raise ScenarioRejectedError(
                    f"not added: {label} is Scenic 2: line {first.line}: `{first.before.strip()[:80]}` ({first.why}); "
                    "pass upgrade_scenic2=True to Bank.add to upgrade it to Scenic 3 (each rewrite is recorded in "
                    "the entry's provenance; `dv2s bank add` does this)", error.stage, findings=error.findings,
                    limit=error.limit) from None
        raise
