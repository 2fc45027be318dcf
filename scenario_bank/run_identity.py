"""The settings that define a resumable run, and the check that a resumed run is the same run.

Every resumable command (``dv2s train`` and fine-tuning, ``dv2s mine``, ``dv2s loop``, a DAgger fine-tuning)
records the settings that make its result what it is when it starts, and compares them with the settings
of the call that resumes it: a difference is refused with :class:`RunIdentityError`, which names every
setting that differs (the recorded and the asked value) and the fix. Settings that only change how the
run goes (workers, progress bars) are not part of a run's identity.
"""

from __future__ import annotations

import json
from typing import Any, List, Mapping, Optional, Sequence, Type

from scenario_bank.errors import DV2SError

__all__ = ["RunIdentityError", "identity_of", "differing", "check_identity"]

_SHOWN = 3
"""Differences spelled out in a refusal (the rest are counted)."""


class RunIdentityError(DV2SError, ValueError):
    """A run folder holds a run made with other settings than the ones asked to resume it.

    ``differences`` lists ``(setting, recorded value, asked value)`` for every setting that differs.
    """

    def __init__(self, message: str, differences: Sequence[tuple] = ()) -> None:
        super().__init__(message)
        self.differences = list(differences)


def identity_of(settings: Mapping[str, Any], keys: Sequence[str]) -> dict:
    """The identity part of ``settings``: the ``keys`` it defines, as JSON-safe values."""
    return json.loads(json.dumps({key: settings.get(key) for key in keys}, default=str))


def _same(recorded: Any, asked: Any) -> bool:
    """Equal as Python values or as JSON (a tuple asked against the list JSON gives back, 1 against 1.0)."""
    if recorded == asked:
        return True
    return json.dumps(recorded, sort_keys=True, default=str) == json.dumps(asked, sort_keys=True, default=str)


def differing(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str]) -> List[str]:
    """The ``keys`` whose values differ between ``recorded`` and ``asked``, in ``keys``' order (a setting one
    of them lacks is ``None`` there)."""
    return [key for key in keys if not _same(recorded.get(key), asked.get(key))]


def _show(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def check_identity(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str], *, run: str,
                   fix: str, notes: Optional[Mapping[str, str]] = None,
                   error: Type[RunIdentityError] = RunIdentityError) -> None:
    """Refuse to resume ``run`` (e.g. ``"out/mine holds a mining run"``) when any of ``keys`` differs.

    Raises:
        RunIdentityError: ``"<run> with other settings (<key>: run has <old>, asked <new>; ...); <fix>"``;
            ``notes`` adds a parenthesised why to a setting (a derived one, such as a file's hash). ``error``:
            the subclass raised (a command's own, such as ``dv2s regress``'s ``ResumeMismatchError``).
    """
    keys_differing = differing(recorded, asked, keys)
    if not keys_differing:
        return
    differences = [(key, recorded.get(key), asked.get(key)) for key in keys_differing]
    shown = [f"{key}: run has {_show(old)}, asked {_show(new)}{(notes or {}).get(key, '')}"
             for key, old, new in differences[:_SHOWN]]
    if len(differences) > _SHOWN:
        shown.append(f"and {len(differences) - _SHOWN} more")
    raise error(f"{run} with other settings ({'; '.join(shown)}); {fix}", differences)
