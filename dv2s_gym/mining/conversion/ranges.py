"""The ranges a script's global parameters draw from, as the conversion's judge reads them.

:func:`script_ranges` reads each numeric parameter's interval (``Range``/``Uniform`` and their affine expressions,
``Normal`` read as ``mean ± NORMAL_SPREAD * sd``), :func:`script_supports` the values of a distribution that is not
one interval (``Uniform(5, 9)``, ``DiscreteRange``); :func:`comparison_contains` says whether a failing value is one
the script produces, and :func:`exact_number` writes a number so a value outside never prints as one inside.
"""

from __future__ import annotations

import re
from typing import Any, Dict, List, Mapping, Optional, Tuple

from dv2s_gym.mining.conversion.param_meaning import script_parameters
from dv2s_gym.mining.conversion.scenic_values import quantity_of, read_interval, read_support, support_contains, support_hull
from scenario_bank.dedup import param_ranges

__all__ = ["script_ranges", "NORMAL_SPREAD", "script_supports", "comparison_contains", "exact_number"]


def script_ranges(script: str) -> Dict[str, Tuple[float, float]]:
    """``{parameter: (low, high)}`` of the script's numeric parameters: :func:`scenario_bank.dedup.param_ranges`'s
    forms, the affine expressions of ``Range``/``Uniform``/numbers
    :func:`~dv2s_gym.mining.conversion.scenic_values.read_interval` reads, and ``Normal(mean, sd)`` read as
    ``mean ± NORMAL_SPREAD * sd`` (:data:`NORMAL_SPREAD`)."""
    ranges: Dict[str, Tuple[float, float]] = {}
    for name, text in script_parameters(script).items():
        interval = read_interval(text)
        if interval is None:
            interval = _normal_interval(text)
        if interval is not None:
            ranges[name] = interval
    ranges.update(param_ranges(script))
    for name, parts in script_supports(script).items():
        ranges.setdefault(name, support_hull(parts))
    return ranges


NORMAL_SPREAD = 3.0
"""A parameter drawn from ``Normal(mean, sd)`` is read as the interval ``mean ± NORMAL_SPREAD * sd``: a normal draw
falls there 997 times in 1000, so a failing value inside is one the new script draws in practice, and one outside
is one it almost never draws."""


_NORMAL = re.compile(r"^\s*Normal\s*\(\s*(-?\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*\)\s*(#.*)?$")


def _normal_interval(text: str) -> Optional[Tuple[float, float]]:
    """``(mean - NORMAL_SPREAD * sd, mean + NORMAL_SPREAD * sd)`` for ``Normal(mean, sd)`` of numbers (sd > 0), else
    ``None``."""
    match = _NORMAL.match(text)
    if match is None or float(match.group(2)) <= 0:
        return None
    mean, spread = float(match.group(1)), NORMAL_SPREAD * float(match.group(2))
    return mean - spread, mean + spread


def script_supports(script: str) -> Dict[str, List[Any]]:
    """``{parameter: its values part by part}`` (:func:`~dv2s_gym.mining.conversion.scenic_values.read_support`) of the
    script's parameters whose distribution is not one interval: ``Uniform(5, 9)`` takes 5 or 9, never 6;
    ``DiscreteRange(5, 9)`` integers only."""
    supports: Dict[str, List[Any]] = {}
    for name, text in script_parameters(script).items():
        parts = read_support(text)
        if parts is None:
            continue
        single = len(parts) == 1 and (parts[0][0] == "interval" or (parts[0][0] == "points" and len(parts[0][1]) == 1)
                                      or (parts[0][0] == "grid" and parts[0][3] == 1))
        if not single:
            supports[name] = [list(part) for part in parts]
    return supports


def comparison_contains(name: str, comparison: Mapping[str, Any]) -> bool:
    """Whether the comparison's quantity (the failing value, or its quantity in the parent) is one the new script
    produces: inside the interval (``interval`` or ``range``) and, for a distribution that is not one interval
    (``support``), among its values (through the new script's ``expression`` when there is one)."""
    low, high = comparison.get("interval") or comparison["range"]
    quantity = float(comparison.get("quantity", comparison["value"]))
    if not low - 1e-9 <= quantity <= high + 1e-9:
        return False
    support = comparison.get("support")
    if not support:
        return True
    function = None
    if comparison.get("expression"):
        function = quantity_of(comparison["expression"], comparison.get("script_name", name))
        if function is None:
            return True  # read at the comparison; unreachable
    return support_contains([tuple(part) for part in support], quantity, function)


def exact_number(number: float) -> str:
    """``number`` short (``10``) when that is exact, else every digit it takes (a range end is never rounded)."""
    short = f"{number:g}"
    return short if float(short) == number else repr(number)
