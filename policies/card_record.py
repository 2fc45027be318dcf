"""The typed model card: :class:`ModelCard`, the record of a checkpoint's ``model_card.json``, and
:class:`FineTune`, its ``fine_tune`` section.

The card is written by ``dv2s train``, fine-tuning and DAgger (:mod:`policies.model_card` writes and renders it,
:func:`policies.registry.read_model_card` reads the one beside a checkpoint) and read by everything that loads a
trained policy: the registry (its ``algorithm`` picks the loader), fine-tuning (its ``env_config`` and
``hyperparameters``), the closed loop (its ``fine_tune`` section) and the regression report (the card of each
policy). Like the records of :mod:`scenario_bank.records`, :meth:`~ModelCard.from_dict` checks every field it
knows and :meth:`~ModelCard.to_dict` gives back the JSON object the file holds, byte for byte once written with
sorted keys. The held-out ``evaluation`` is a :class:`CardEvaluation`, each policy's part of it a
:class:`CardResults` with its :class:`CardOverall`; the sections that are free-form JSON (hyperparameters, env
config, bank, sampler, training, versions) and the evaluation's leaves (the rates ``{"k", "n", "rate", "lo",
"hi"}``, the per-scenario rates and the paired ``comparisons``) stay JSON objects.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, ClassVar, FrozenSet, Mapping, Optional, Tuple

from scenario_bank.records import JsonRecord

__all__ = ["FineTuneMethod", "FINE_TUNE_METHODS", "FineTune", "CardOverall", "CardResults", "CardEvaluation",
           "ModelCard"]


class FineTuneMethod(str, enum.Enum):
    """How a checkpoint was fine-tuned: ``PPO``, by reinforcement learning with the checkpoint's own algorithm on
    reweighted scenarios (:func:`policies.training.fine_tune`, whose card section names no ``method``), or
    ``DAGGER``, by imitating a reference driver (:func:`policies.imitation.dagger_fine_tune`). A member is its
    JSON string (``"ppo"``, ``"dagger"``) and equals it."""

    PPO = "ppo"
    DAGGER = "dagger"


FINE_TUNE_METHODS: Tuple[str, ...] = tuple(method.value for method in FineTuneMethod)
"""The fine-tuning methods by name, as options and files spell them: ``("ppo", "dagger")``."""


@dataclass(frozen=True, eq=False)
class FineTune(JsonRecord):
    """A card's ``fine_tune`` section: where the model was fine-tuned from (``source``, ``source_checkpoint``,
    ``source_steps``), for how many ``steps``, on which scenario ``weights``, at which ``learning_rate`` and, for
    an RL fine-tune, with which ``reward_weights`` overrides. A DAgger fine-tune (``method == "dagger"``) adds its
    ``reference`` driver, the DAgger settings (``iterations``, ``beta``, ``beta_decay``, ``epochs``,
    ``batch_size``, ``slower_weight``, ``disagreement_weight``), the per-iteration ``history``, the ``agreement``
    with the reference before and after, and the runs it was ``resumed`` from."""

    agreement: Optional[Mapping[str, Any]] = None
    batch_size: Optional[int] = None
    beta: Optional[float] = None
    beta_decay: Optional[float] = None
    disagreement_weight: Optional[float] = None
    epochs: Optional[int] = None
    history: Optional[Tuple[Any, ...]] = None
    iterations: Optional[int] = None
    learning_rate: Optional[float] = None
    method: Optional[str] = None
    reference: Optional[str] = None
    resumed: Optional[Tuple[Any, ...]] = None
    reward_weights: Optional[Mapping[str, Any]] = None
    slower_weight: Optional[float] = None
    source: Optional[str] = None
    source_checkpoint: Optional[str] = None
    source_steps: Optional[int] = None
    steps: Optional[int] = None
    weights: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # sorted, as the card file is written
    _WHAT: ClassVar[str] = "model card fine_tune"

    @property
    def kind(self) -> FineTuneMethod:
        """The fine-tuning method; a section naming none is an RL fine-tune (:attr:`FineTuneMethod.PPO`)."""
        return FineTuneMethod(self.method) if self.method is not None else FineTuneMethod.PPO

    @property
    def is_dagger(self) -> bool:
        """Whether the model was fine-tuned by DAgger."""
        return self.method == FineTuneMethod.DAGGER.value


@dataclass(frozen=True, eq=False)
class CardOverall(JsonRecord):
    """A policy's overall results in a card's evaluation: the ``collision``, ``success``, ``off_road`` and
    ``failure`` rates (each ``{"k", "n", "rate", "lo", "hi"}``, episodes with an error left out), the ``episodes``
    run, the ``errors`` among them and the ``mean_return`` and ``mean_speed`` of the others."""

    collision: Optional[Mapping[str, Any]] = None
    episodes: Optional[int] = None
    errors: Optional[int] = None
    failure: Optional[Mapping[str, Any]] = None
    mean_return: Optional[float] = None
    mean_speed: Optional[float] = None
    off_road: Optional[Mapping[str, Any]] = None
    success: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # sorted, as the card file is written
    _WHAT: ClassVar[str] = "model card results overall"

    def measure(self, name: str) -> Mapping[str, Any]:
        """The rate of measure ``name`` (``"collision"``, ``"success"``, ``"off_road"`` or ``"failure"``)."""
        return {"collision": self.collision, "success": self.success, "off_road": self.off_road,
                "failure": self.failure}[name]


@dataclass(frozen=True, eq=False)
class CardResults(JsonRecord):
    """One policy's results in a card's evaluation: ``overall`` (:class:`CardOverall`), the rates of each scenario
    (``per_scenario``: ``{name: {measure: rate}}``) and every episode's outcome code per scenario (``outcomes``,
    :func:`policies.model_card.outcome_code`)."""

    outcomes: Optional[Mapping[str, str]] = None
    overall: Optional[CardOverall] = None
    per_scenario: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # sorted, as the card file is written
    _WHAT: ClassVar[str] = "model card results"


@dataclass(frozen=True, eq=False)
class CardEvaluation(JsonRecord):
    """A card's held-out ``evaluation`` (:func:`policies.model_card.evaluation_section`): the ``confidence`` and
    ``interval`` of its rates, the ``alpha`` of its tests, the ``candidate`` label, the episodes
    (``episodes_total``: the ``scenarios`` x ``seeds_per_scenario`` seeds from ``seed_base``), each label's policy
    ``specs``, its :class:`CardResults` (``policies``), the paired ``comparisons`` of the candidate against every
    other label (``{label: {measure: comparison}}``) and the ``summary`` sentences."""

    alpha: Optional[float] = None
    candidate: Optional[str] = None
    comparisons: Optional[Mapping[str, Any]] = None
    confidence: Optional[float] = None
    episodes_total: Optional[int] = None
    interval: Optional[str] = None
    policies: Optional[Mapping[str, CardResults]] = None
    scenarios: Optional[Tuple[str, ...]] = None
    seed_base: Optional[int] = None
    seeds_per_scenario: Optional[int] = None
    specs: Optional[Mapping[str, str]] = None
    summary: Optional[Tuple[str, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # sorted, as the card file is written
    _WHAT: ClassVar[str] = "model card evaluation"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"seed_base", "seeds_per_scenario"})


@dataclass(frozen=True, eq=False)
class ModelCard(JsonRecord):
    """A checkpoint's model card (``model_card.json``): its ``name`` and ``description``, the ``algorithm``
    (``ppo``, ``dqn``, ``sac``, ...) and ``policy`` network, the ``hyperparameters``, the ``env_id`` and
    ``env_config`` it was trained in and its ``observation_space``/``action_space``, the ``bank`` version and
    scenarios, the scenario ``sampler``, the ``training`` run (command, steps, seed, wall time, segments), the
    library ``versions``, the held-out ``evaluation`` (a :class:`CardEvaluation`; ``null`` when it was
    interrupted, absent when skipped; see :mod:`policies.model_card`) and, for a fine-tuned model, its ``fine_tune`` section (:class:`FineTune`).

    A checkpoint without a card reads as the empty card (every field ``None``, :attr:`exists` false)."""

    action_space: Optional[str] = None
    algorithm: Optional[str] = None
    bank: Optional[Mapping[str, Any]] = None
    card_version: Optional[int] = None
    description: Optional[str] = None
    env_config: Optional[Mapping[str, Any]] = None
    env_id: Optional[str] = None
    evaluation: Optional[CardEvaluation] = None
    fine_tune: Optional[FineTune] = None
    hyperparameters: Optional[Mapping[str, Any]] = None
    name: Optional[str] = None
    observation_space: Optional[str] = None
    policy: Optional[str] = None
    sampler: Optional[Mapping[str, Any]] = None
    training: Optional[Mapping[str, Any]] = None
    versions: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    # sorted, as the card file is written
    _WHAT: ClassVar[str] = "model card"

    @property
    def exists(self) -> bool:
        """Whether the card holds anything (a checkpoint without a card reads as the empty card)."""
        return bool(self.to_dict())

    @property
    def evaluation_interrupted(self) -> bool:
        """Whether the card's held-out evaluation was interrupted (``evaluation`` written as ``null``)."""
        return self.evaluation is None and "evaluation" in (self.null_fields or ())

    def with_algorithm(self, algorithm: str) -> "ModelCard":
        """This card, naming ``algorithm`` when it names none (a bare checkpoint found to load as one)."""
        return self if self.algorithm else self.replace(algorithm=algorithm)
