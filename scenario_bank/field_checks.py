"""Checks for the fields of the settings dataclasses: each raises the caller's own error class with a message
naming the field (as its command-line flag where it has one), the bad value and what is allowed.

Every check takes ``error`` (a :class:`~scenario_bank.errors.DV2SError` subclass) and ``name`` (``"--budget"``
or ``"DAgger beta"``) first, and returns the value it accepted (unchanged, except :func:`check_names`, which
returns a tuple). Booleans are never accepted as numbers: ``True`` for a count is a mistake, not 1.
"""

from __future__ import annotations

import math
import os
from typing import Any, Collection, Mapping, Optional, Tuple, Type

from scenario_bank.errors import DV2SError, SettingError

__all__ = ["check_int", "check_number", "check_bool", "check_choice", "check_names", "check_text", "check_path",
           "check_mapping"]


def _refuse(error: Type[DV2SError], name: str, allowed: str, value: Any) -> DV2SError:
    return error(f"{name} must be {allowed}, not {value!r}")


def _range_text(low: Optional[float], high: Optional[float], low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f"{'<' if high_open else '<='} {high:g}"
    return ""


def check_int(error: Type[DV2SError], name: str, value: Any, *, low: Optional[int] = None,
              high: Optional[int] = None, optional: bool = False, none_means: str = "") -> Optional[int]:
    """``value`` as a whole number in ``[low, high]`` (either bound may be left out); ``None`` when ``optional``
    (``none_means`` says what it means in the message)."""
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or (low is not None and value < low) or \
            (high is not None and value > high):
        bounds = ("an integer" if low is None and high is None
                  else f"an integer {_range_text(low, high, False, False)}")
        if optional:
            bounds += f" or left out{' (' + none_means + ')' if none_means else ''}"
        raise _refuse(error, name, bounds, value)
    return value


def check_number(error: Type[DV2SError], name: str, value: Any, *, low: Optional[float] = None,
                 high: Optional[float] = None, interval: str = "[]", optional: bool = False,
                 example: str = "") -> Optional[float]:
    """``value`` as a finite real number within the bounds; ``interval`` says which bounds are excluded, as the
    brackets of an interval (``"[)"``: ``low <= value < high``, ``"(]"``: ``low < value``); ``None`` when
    ``optional``. ``example`` is appended to the message (``"e.g. 0.05"``)."""
    if interval not in ("[]", "(]", "[)", "()"):
        raise SettingError(f"interval must be one of [], (], [), (), not {interval!r}")
    if value is None and optional:
        return None
    low_open, high_open = interval[0] == "(", interval[1] == ")"
    ok = (not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
          and (low is None or (value > low if low_open else value >= low))
          and (high is None or (value < high if high_open else value <= high)))
    if not ok:
        if low is None and high is None:
            allowed = "a finite number"
        elif low == 0 and high is None:
            allowed = "a positive number" if low_open else "a number >= 0"
        else:
            allowed = f"a number {_range_text(low, high, low_open, high_open)}"
        allowed += " or left out" if optional else ""
        allowed += f", {example}" if example else ""
        raise _refuse(error, name, allowed, value)
    return value


def check_bool(error: Type[DV2SError], name: str, value: Any) -> bool:
    """``value`` as ``True`` or ``False`` (not a string or a number)."""
    if not isinstance(value, bool):
        raise _refuse(error, name, "True or False", value)
    return value


def check_choice(error: Type[DV2SError], name: str, value: Any, choices: Collection[str], *,
                 optional: bool = False) -> Optional[str]:
    """``value`` as one of ``choices``; ``None`` when ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, str) or value not in choices:
        raise _refuse(error, name, f"one of {', '.join(choices)}{' or left out' if optional else ''}", value)
    return value


def check_text(error: Type[DV2SError], name: str, value: Any, *, optional: bool = False,
               what: str = "a non-empty string") -> Optional[str]:
    """``value`` as a non-empty string; ``None`` when ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value.strip():
        raise _refuse(error, name, what + (" or left out" if optional else ""), value)
    return value


def check_path(error: Type[DV2SError], name: str, value: Any, *, optional: bool = False) -> Any:
    """``value`` as a non-empty path (a string or an ``os.PathLike``); ``None`` when ``optional``."""
    if value is None and optional:
        return None
    if isinstance(value, os.PathLike):
        value_text = os.fspath(value)
    else:
        value_text = value
    if not isinstance(value_text, str) or not value_text.strip():
        raise _refuse(error, name, "a folder path" + (" or left out" if optional else ""), value)
    return value


def check_names(error: Type[DV2SError], name: str, value: Any, *, optional: bool = True) -> Optional[Tuple[str, ...]]:
    """``value`` as a tuple of names: one string is one name, a list or tuple of strings its names; ``None`` when
    ``optional``. Blank names are left to the selection that reads them (which reports an empty one)."""
    if value is None and optional:
        return None
    if isinstance(value, str):
        value = (value,)
    allowed = "a list of names" + (" or left out" if optional else "")
    if not isinstance(value, (list, tuple)):
        raise _refuse(error, name, allowed, value)
    for item in value:
        if not isinstance(item, str):
            raise error(f"{name} must be {allowed}; {item!r} in {list(value)!r} is not a name")
    return tuple(value)


def check_mapping(error: Type[DV2SError], name: str, value: Any, *, optional: bool = False,
                  what: str = "a mapping of names to values") -> Optional[Mapping[str, Any]]:
    """``value`` as a mapping with string keys; ``None`` when ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, Mapping) or not all(isinstance(key, str) for key in value):
        raise _refuse(error, name, what + (" or left out" if optional else ""), value)
    return value
