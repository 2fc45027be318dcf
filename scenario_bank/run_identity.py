"""The settings that define a resumable run, and the check that a resumed run is the same run.

Every resumable command (``dv2s train`` and fine-tuning, ``dv2s mine``, ``dv2s loop``, a DAgger fine-tuning)
records the settings that make its result what it is when it starts, and compares them with the settings
of the call that resumes it: a difference is refused with :class:`RunIdentityError`, which names every
setting that differs (the recorded and the asked value) and the fix. Settings that only change how the
run goes (workers, progress bars) are not part of a run's identity.

A setting added to a command after a run folder was written is absent from that folder's record: it compares as
the setting's default (the value the command used before the setting existed, :func:`setting_defaults`), so the
run resumes when the default is asked and is refused, naming the setting, when another value is. A setting
recorded as ``null`` stays ``null``.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Type, Union

from scenario_bank.errors import DV2SError

__all__ = ["RunIdentityError", "identity_of", "differing", "check_identity", "setting", "resume_keys",
           "recorded_settings", "setting_defaults"]

_SHOWN = 3
"""Differences spelled out in a refusal (the rest are counted)."""
_UNRECORDED = " (not recorded: the default)"
"""Said of a recorded value that is the setting's default because the run did not record the setting."""


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


Defaults = Union[type, Mapping[str, Any], None]
"""What a setting absent from a record compares as: a settings dataclass (its fields' defaults,
:func:`setting_defaults`), a mapping of setting to default (recorded JSON values), or ``None`` (no defaults)."""


def _defaults_mapping(defaults: Defaults) -> Mapping[str, Any]:
    if defaults is None:
        return {}
    if isinstance(defaults, type):
        return setting_defaults(defaults)
    return defaults


def _value(settings: Mapping[str, Any], key: str, defaults: Mapping[str, Any]) -> Any:
    """``settings[key]``; when it lacks the key, the key's default (``None`` when it has none)."""
    if key in settings:
        return settings[key]
    return defaults.get(key)


def differing(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str], *,
              defaults: Defaults = None) -> List[str]:
    """The ``keys`` whose values differ between ``recorded`` and ``asked``, in ``keys``' order (a setting one
    of them lacks is its default in ``defaults``, else ``None``)."""
    known = _defaults_mapping(defaults)
    return [key for key in keys if not _same(_value(recorded, key, known), _value(asked, key, known))]


def _show(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def check_identity(recorded: Mapping[str, Any], asked: Mapping[str, Any], keys: Sequence[str], *, run: str,
                   fix: str, defaults: Defaults, notes: Optional[Mapping[str, str]] = None,
                   error: Type[RunIdentityError] = RunIdentityError) -> None:
    """Refuse to resume ``run`` (e.g. ``"out/mine holds a mining run"``) when any of ``keys`` differs.

    ``defaults`` (:data:`Defaults`, the run's settings dataclass or a mapping): what a setting absent from
    ``recorded`` (a run written before the setting existed) or from ``asked`` compares as; a recorded ``None`` is
    ``None``. A setting without a default compares as ``None`` when absent.

    Raises:
        RunIdentityError: ``"<run> with other settings (<key>: run has <old>, asked <new>; ...); <fix>"``;
            ``notes`` adds a parenthesised why to a setting (a derived one, such as a file's hash). ``error``:
            the subclass raised (a command's own, such as ``dv2s regress``'s ``ResumeMismatchError``).
    """
    known = _defaults_mapping(defaults)
    keys_differing = differing(recorded, asked, keys, defaults=known)
    if not keys_differing:
        return
    differences = [(key, _value(recorded, key, known), _value(asked, key, known)) for key in keys_differing]
    shown = [f"{key}: run has {_show(old)}{_UNRECORDED if key not in recorded and key in known else ''}, "
             f"asked {_show(new)}{(notes or {}).get(key, '')}" for key, old, new in differences[:_SHOWN]]
    if len(differences) > _SHOWN:
        shown.append(f"and {len(differences) - _SHOWN} more")
    raise error(f"{run} with other settings ({'; '.join(shown)}); {fix}", differences)


# --------------------------------------------------------------------------- settings dataclasses
_RESUME = "resume"
_RECORD = "record"
_CASTS = {"float": float, "int": int, "bool": bool}


def setting(default: Any = dataclasses.MISSING, *, default_factory: Any = dataclasses.MISSING, resume: bool = True,
            record: Union[bool, Callable[[Any], Any]] = True) -> Any:
    """A field of a run's settings dataclass, saying how a run treats it (a plain field is part of the run's
    identity and recorded as its JSON value).

    ``resume=False``: a resumed run may ask another value (it is not part of the run's identity, :func:`resume_keys`).
    ``record``: ``False`` when the run folder does not record the setting, or the function giving its recorded value
    (instead of :func:`recorded_settings`' plain JSON form)."""
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={_RESUME: resume, _RECORD: record})


def resume_keys(settings_class: type) -> Tuple[str, ...]:
    """The fields of a settings dataclass a resumed run must share with the run it continues, in field order
    (every field but those declared with ``setting(resume=False)``)."""
    return tuple(f.name for f in dataclasses.fields(settings_class) if f.metadata.get(_RESUME, True))


def recorded_settings(settings: Any) -> Dict[str, Any]:
    """The fields of a settings dataclass as its run folder records them (JSON values), in field order: a tuple as a
    list, a mapping as a dict, a value of a ``float``, ``int`` or ``bool`` field as that type (``1`` as ``1.0``);
    a field declared with ``setting(record=...)`` through its function, or left out with ``record=False``."""
    values: Dict[str, Any] = {}
    for field in dataclasses.fields(settings):
        record = field.metadata.get(_RECORD, True)
        if record is False:
            continue
        value = getattr(settings, field.name)
        values[field.name] = record(value) if callable(record) else _json_value(field, value)
    return values


def _json_value(field: dataclasses.Field, value: Any) -> Any:
    if value is None:
        return None
    cast = _CASTS.get(field.type if isinstance(field.type, str) else getattr(field.type, "__name__", ""))
    if cast is not None:
        return cast(value)
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, Mapping):
        return dict(value)
    return value


def setting_defaults(settings_class: type, keys: Optional[Sequence[str]] = None) -> Dict[str, Any]:
    """The default of each field of a settings dataclass that has one, as its run folder records it
    (:func:`recorded_settings`' JSON form; fields declared ``record=False`` have none); only ``keys`` when given."""
    values: Dict[str, Any] = {}
    for field in dataclasses.fields(settings_class):
        record = field.metadata.get(_RECORD, True)
        if record is False or (keys is not None and field.name not in keys):
            continue
        if field.default is not dataclasses.MISSING:
            value = field.default
        elif field.default_factory is not dataclasses.MISSING:
            value = field.default_factory()
        else:
            continue
        values[field.name] = record(value) if callable(record) else _json_value(field, value)
    return values
