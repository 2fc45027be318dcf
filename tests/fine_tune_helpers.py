"""The tests' shorthand for fine-tunings: :func:`policies.training.fine_tune` and
:func:`policies.imitation.dagger_fine_tune` with their configs' fields as keywords."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable

from policies import imitation, training
from policies.dagger_config import DaggerConfig

_DAGGER_FIELDS = {field.name for field in dataclasses.fields(DaggerConfig)}


def _train_config(out: Any, options: dict) -> training.TrainConfig:
    return training.TrainConfig.fine_tuning(out, steps=options.pop("steps"), weights=options.pop("weights"),
                                            **options)


def fine_tune(spec: str, *, out: Any, log: Callable[[str], None] = print, **options: Any) -> Path:
    """:func:`policies.training.fine_tune` with the :class:`~policies.training.TrainConfig` fields as keywords."""
    return training.fine_tune(spec, _train_config(out, options), log=log)


def dagger_fine_tune(spec: str, *, out: Any, log: Callable[[str], None] = print, **options: Any) -> Path:
    """:func:`policies.imitation.dagger_fine_tune` with the :class:`~policies.imitation.DaggerConfig` and
    :class:`~policies.training.TrainConfig` fields as keywords (``learning_rate`` goes to DAgger)."""
    dagger = DaggerConfig(**{key: options.pop(key) for key in list(options) if key in _DAGGER_FIELDS})
    return imitation.dagger_fine_tune(spec, _train_config(out, options), dagger, log=log)
