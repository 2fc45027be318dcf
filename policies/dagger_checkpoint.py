"""The checkpoint of an unfinished DAgger run (:func:`policies.imitation.dagger_fine_tune`), one per iteration.

After every iteration the run writes, into ``out/dagger_checkpoint/`` (all atomic):

- ``iteration_<i>.npz``: the states labelled in iteration ``i`` (``observations``, ``labels``,
  ``disagreed``: whether the student's greedy action there was not the label) and the training
  envs' observations when it ended (``next_observations``); the aggregated
  data set after iteration ``k`` is ``iteration_1 .. iteration_k`` in order;
- ``weights_<k>.pt``: the policy's parameters, Adam's state and torch's RNG state after
  iteration ``k``'s training (the previous iteration's file is removed once ``k`` is committed);
- ``progress.json`` (written last: the commit): the run's identity (:func:`run_identity`: its settings, the code
  it runs and the reference driver's fingerprint), the
  number ``k`` of finished iterations, their stats, the minibatch-order RNG's state, each
  training env's position (:meth:`policies.imitation.ReferenceLabels.snapshot`), the wall
  time spent so far and the earlier resumes.

While iteration ``k + 1`` collects, every ``checkpoint_every`` env steps the states labelled so
far go to ``partial_<k+1>_<rows>.npz`` and ``progress.json`` gains a ``partial`` record (rows,
episode counts, the envs' positions); a kill during collection then loses at most that many
steps (one during training loses the iteration's training, not its collection).

A run killed at any point restarts from the last commit and ends with the same model as an
uninterrupted one (the envs are put back where they were by replaying the current episode's
actions). A checkpoint whose identity differs from the new call's is refused
(:class:`~scenario_bank.run_identity.RunIdentityError`), never mixed in: other settings, other code
(:func:`~policies.run_identity.check_code_unchanged`: dv2s's sources, the plug-ins, the user's files the code read) or a
reference driver replaced or edited since (:func:`~policies.run_identity.check_policy_unchanged`), whose labels would
otherwise be mixed with the first one's.
"""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional

import numpy as np

from policies.dagger_config import DaggerConfig
from policies.run_identity import CODE_IDENTITY, check_code_unchanged, check_policy_unchanged, code_identity, \
    resume_fingerprint
from policies.training import TrainingError
from scenario_bank.run_identity import RunIdentityError, bank_identity, check_format, check_identity, record_format
from scenario_bank.atomic import atomic_write_bytes, atomic_write_json, file_sha256
from scenario_bank.bank import Bank
from scenario_bank.run_paths import as_read, read_paths, record_paths, resume_fix

if TYPE_CHECKING:
    from policies.training import TrainConfig

__all__ = ["CHECKPOINT_DIR", "DAggerResumeError", "DAggerCheckpoint", "LabelledBatch", "SavedIteration", "PartialIteration",
           "run_identity", "describe_position", "REFERENCE_FINGERPRINT"]

CHECKPOINT_DIR = "dagger_checkpoint"
"""The checkpoint's folder inside the fine-tuning run's ``out``."""

SCHEMA = "dv2s-dagger-checkpoint"
VERSION = 3
"""The format of ``progress.json`` (bumped when its fields change; a checkpoint of another format is refused)."""

IDENTITY_ORDER = ("steps", "iterations", "epochs", "batch_size", "learning_rate", "beta", "beta_decay", "reference",
                  "seed", "n_envs", "weights", "env_config", "bank_dir", "source", "source_sha256", "scenario_hashes")
"""The order in which a refused checkpoint's settings are compared (the first difference is named)."""

REFERENCE_FINGERPRINT = "reference_fingerprint"
"""The key under which a checkpoint's identity records the reference driver's
:func:`~policies.run_identity.resume_fingerprint`."""

_DERIVED = {"source_sha256": " (the source checkpoint's file changed)",
            "scenario_hashes": " (the bank's scenario scripts changed)"}


class DAggerResumeError(TrainingError):
    """A DAgger checkpoint that cannot be resumed because its files are unreadable (one written with other
    settings is refused with :class:`~scenario_bank.run_identity.RunIdentityError`)."""


@dataclasses.dataclass
class LabelledBatch:
    """The states one iteration labelled, as committed when it finishes."""

    iteration: int
    """The iteration (1-based)."""
    observations: np.ndarray
    labels: np.ndarray
    next_observations: np.ndarray
    """The training envs' observations when the iteration ended."""
    disagreed: Optional[np.ndarray] = None
    """Per state, whether the student that collected it (the policy at the iteration's start) greedily chose
    another action than the label (``None``: not recorded, read back as all ``False``)."""


def _npz_bytes(batch: "LabelledBatch | PartialIteration") -> bytes:
    buffer = io.BytesIO()
    arrays = {"observations": batch.observations, "labels": batch.labels,
              "next_observations": batch.next_observations}
    if getattr(batch, "disagreed", None) is not None:
        arrays["disagreed"] = np.asarray(batch.disagreed, dtype=bool)
    np.savez(buffer, **arrays)
    return buffer.getvalue()


@dataclasses.dataclass
class PartialIteration:
    """The states labelled so far in an iteration that was still collecting when the run stopped."""

    iteration: int
    """The iteration collecting (1-based)."""
    observations: np.ndarray
    labels: np.ndarray
    next_observations: np.ndarray
    """The training envs' observations at that point."""
    episodes: int
    crashes: int
    envs: List[Dict[str, Any]]

    @property
    def rows(self) -> int:
        """Labelled states collected in the iteration so far."""
        return int(len(self.labels))


@dataclasses.dataclass
class SavedIteration:
    """A committed checkpoint, loaded: everything needed to run iteration ``iteration + 1``."""

    iteration: int
    """Finished iterations."""
    observations: List[np.ndarray]
    labels: List[np.ndarray]
    next_observations: np.ndarray
    """The training envs' observations when iteration ``iteration`` ended."""
    weights: Optional[Dict[str, Any]]
    """``{"policy": state_dict, "optimizer": state_dict, "torch_rng": ByteTensor}`` (``None`` before
    the first iteration's training: the source's)."""
    rng_state: Dict[str, Any]
    history: List[Dict[str, Any]]
    envs: List[Dict[str, Any]]
    wall_time_s: float
    resumes: List[Dict[str, Any]]
    partial: Optional[PartialIteration] = None
    disagreed: List[np.ndarray] = dataclasses.field(default_factory=list)
    """Per finished iteration, :attr:`LabelledBatch.disagreed` (all ``False`` where not recorded)."""


def _scenario_hashes(bank_dir: Optional[str], names: List[str]) -> Dict[str, Optional[str]]:
    """Each scenario's script SHA-256 as it is on disk (:func:`~scenario_bank.run_identity.bank_identity`; ``None``
    when the bank does not hold it)."""
    bank = Bank(bank_dir) if bank_dir is not None else Bank()
    scripts = bank_identity(bank, [name for name in names if name in bank])
    return {name: scripts.get(name) for name in names}


def run_identity(*, source: str, source_checkpoint: Path, config: "TrainConfig", dagger: "DaggerConfig",
                 weights: Mapping[str, float], env_config: Mapping[str, Any]) -> Dict[str, Any]:
    """The settings a checkpoint must share with a call to resume it (JSON-safe): everything that changes
    the result (the source checkpoint's bytes, the bank's scenario scripts, the sampling ``weights``, the
    ``env_config``, ``config``'s steps, seed and environments, every ``dagger`` setting but how often it
    commits), not how it runs (``vec_env``, the progress bar); and the code it runs
    (:data:`~policies.run_identity.CODE_IDENTITY`, but the files under its ``out`` folder and its bank) and the
    reference driver's fingerprint (:data:`REFERENCE_FINGERPRINT`)."""
    names, bank_dir, d = sorted(weights), config.bank_dir, dagger
    own = [config.out, bank_dir]
    return json.loads(json.dumps({
        CODE_IDENTITY: code_identity(exclude=own), REFERENCE_FINGERPRINT: resume_fingerprint(str(d.reference)),
        "source": str(source), "source_sha256": file_sha256(source_checkpoint),
        "bank_dir": None if bank_dir is None else str(Path(bank_dir).resolve()),
        "weights": {name: float(weights[name]) for name in names},
        "scenario_hashes": _scenario_hashes(bank_dir, names), "env_config": dict(env_config),
        "steps": int(config.steps), "iterations": int(d.iterations), "beta": float(d.beta),
        "beta_decay": float(d.beta_decay), "epochs": int(d.epochs), "batch_size": int(d.batch_size),
        "learning_rate": float(d.learning_rate), "reference": str(d.reference), "slower_weight": float(d.slower_weight),
        "disagreement_weight": float(d.disagreement_weight),
        "seed": int(config.seed), "n_envs": int(config.n_envs)}, sort_keys=True))


class DAggerCheckpoint:
    """The checkpoint folder of one DAgger run (module docstring); ``identity`` is the current call's."""

    def __init__(self, folder: Path, identity: Mapping[str, Any]) -> None:
        self.folder = Path(folder)
        self.identity = dict(identity)
        self._committed: Optional[Dict[str, Any]] = None

    @property
    def progress_path(self) -> Path:
        return self.folder / "progress.json"

    def _progress(self) -> Optional[Dict[str, Any]]:
        if not self.progress_path.is_file():
            return None
        try:
            data = json.loads(self.progress_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            data, problem = None, str(error)
        else:
            if isinstance(data, dict) and data.get("schema") == SCHEMA:
                check_format(data, SCHEMA, VERSION, folder=self.folder, what="the checkpoint of an unfinished DAgger "
                             "run", file=self.progress_path.name, error=DAggerResumeError)
            problem = _progress_problem(data)
        if problem:
            raise DAggerResumeError(f"the DAgger checkpoint {self.progress_path} is unreadable ({problem}); delete "
                                    f"{self.folder} to start the fine-tuning over")
        return data

    def load(self) -> Optional[SavedIteration]:
        """The last committed iteration, or ``None`` when there is none (a fresh run).

        Raises:
            RunIdentityError: the checkpoint was written with other settings (the message names the
                settings that differ and both values).
            DAggerResumeError: its files are unreadable.
        """
        data = self._progress()
        if data is None:
            return None
        # paths in the fine-tuning's folder or the loop folder holding it, where they are now (a moved folder resumes)
        recorded = read_paths(data.get("identity") or {}, self.folder.parent)
        asked = as_read(self.identity, self.folder.parent)
        settings = [{key: value for key, value in identity.items() if key not in _CHECKED_APART}
                    for identity in (recorded, asked)]
        keys = [key for key in IDENTITY_ORDER if key in settings[0] or key in settings[1]]
        check_identity(settings[0], settings[1], keys + sorted((set(settings[0]) | set(settings[1])) - set(keys)),
                       run=f"{self.folder} holds an unfinished DAgger run", notes=_DERIVED,
                       fix=resume_fix(self.folder.parent, f"pass the same settings to resume it, or delete "
                                                          f"{self.folder} to start over"))
        self._check_code(recorded, asked)
        iteration = int(data["iteration"])
        try:
            observations, labels, disagreed, next_observations = [], [], [], None
            for number in range(1, iteration + 1):
                with np.load(self.folder / f"iteration_{number}.npz") as batch:
                    observations.append(batch["observations"])
                    labels.append(batch["labels"])
                    disagreed.append(batch["disagreed"] if "disagreed" in batch.files
                                     else np.zeros(len(batch["labels"]), dtype=bool))
                    next_observations = batch["next_observations"]
            weights = None
            if iteration:
                import torch

                weights = torch.load(self.folder / f"weights_{iteration}.pt", map_location="cpu", weights_only=True)
            partial = None
            if data.get("partial"):
                record = data["partial"]
                with np.load(self.folder / record["file"]) as batch:
                    partial = PartialIteration(
                        iteration=int(record["iteration"]), observations=batch["observations"],
                        labels=batch["labels"], next_observations=batch["next_observations"],
                        episodes=int(record["episodes"]), crashes=int(record["crashes"]), envs=list(record["envs"]))
        except (OSError, KeyError, ValueError, RuntimeError, TypeError) as error:
            raise DAggerResumeError(f"the DAgger checkpoint in {self.folder} is incomplete ({error}); delete "
                                    f"{self.folder} to start the fine-tuning over") from None
        self._committed = {key: value for key, value in data.items() if key != "partial"}
        return SavedIteration(iteration=iteration, observations=observations, labels=labels,
                              next_observations=next_observations, weights=weights, rng_state=data["rng"],
                              history=list(data["history"]), envs=list(data["envs"]),
                              wall_time_s=float(data.get("wall_time_s", 0.0)), resumes=list(data.get("resumes", [])),
                              partial=partial, disagreed=disagreed)

    def _check_code(self, recorded: Mapping[str, Any], asked: Mapping[str, Any]) -> None:
        """Refuse a checkpoint made with other code or with a reference driver changed since (each fact named), as
        every resumable run is refused (:mod:`policies.run_identity`); an identity with neither asks nothing."""
        run = f"{self.folder} holds an unfinished DAgger run"
        if CODE_IDENTITY in recorded or CODE_IDENTITY in asked:
            check_code_unchanged(recorded, run=run, error=RunIdentityError, now=asked.get(CODE_IDENTITY) or {})
        if REFERENCE_FINGERPRINT in recorded or REFERENCE_FINGERPRINT in asked:
            check_policy_unchanged(recorded, str(asked.get("reference", recorded.get("reference"))),
                                   folder=self.folder.parent, run="DAgger run", error=RunIdentityError,
                                   key=REFERENCE_FINGERPRINT, role="reference driver")

    def save(self, batch: LabelledBatch, *, model: Any, optimizer: Any, rng: np.random.Generator,
             history: List[Dict[str, Any]], envs: List[Dict[str, Any]], wall_time_s: float,
             resumes: List[Dict[str, Any]]) -> None:
        """Commit iteration ``batch.iteration`` (its new labelled states, the weights after its training, the
        RNGs, the envs' positions); a kill at any point leaves the previous commit intact."""
        import torch

        iteration = batch.iteration
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self.folder / f"iteration_{iteration}.npz", _npz_bytes(batch))
        buffer = io.BytesIO()
        torch.save({"policy": model.policy.state_dict(), "optimizer": optimizer.state_dict(),
                    "torch_rng": torch.get_rng_state()}, buffer)
        atomic_write_bytes(self.folder / f"weights_{iteration}.pt", buffer.getvalue())
        identity = record_paths(self.identity, self.folder.parent)
        self._committed = {**record_format(SCHEMA, VERSION), "identity": identity, "iteration": int(iteration), "history": history, "rng": rng.bit_generator.state, "envs": envs,
                           "wall_time_s": round(float(wall_time_s), 3), "resumes": resumes}
        atomic_write_json(self.progress_path, {**self._committed, "partial": None})
        (self.folder / f"weights_{iteration - 1}.pt").unlink(missing_ok=True)
        self._remove_partials(keep=None)

    def save_partial(self, partial: PartialIteration, *, rng: np.random.Generator, resumes: List[Dict[str, Any]],
                     wall_time_s: float) -> None:
        """Commit the states iteration ``partial.iteration`` (1-based, still collecting) has labelled so far,
        with the envs' positions; the last finished iteration's commit stays as it was."""
        self.folder.mkdir(parents=True, exist_ok=True)
        name = f"partial_{partial.iteration}_{partial.rows}.npz"
        atomic_write_bytes(self.folder / name, _npz_bytes(partial))
        committed = self._committed or {
            **record_format(SCHEMA, VERSION), "identity": record_paths(self.identity, self.folder.parent), "iteration": 0, "history": [],
            "rng": rng.bit_generator.state, "envs": []}
        atomic_write_json(self.progress_path, {
            **committed, "wall_time_s": round(float(wall_time_s), 3), "resumes": resumes,
            "partial": {"iteration": int(partial.iteration), "file": name, "rows": partial.rows,
                        "episodes": int(partial.episodes), "crashes": int(partial.crashes), "envs": partial.envs}})
        self._remove_partials(keep=name)

    def _remove_partials(self, keep: Optional[str]) -> None:
        for path in self.folder.glob("partial_*.npz"):
            if path.name != keep:
                path.unlink(missing_ok=True)

    def remove(self) -> None:
        """Delete the folder (the run is finished: its model and card are written)."""
        shutil.rmtree(self.folder, ignore_errors=True)


_CHECKED_APART = (CODE_IDENTITY, REFERENCE_FINGERPRINT)
"""The facts of a checkpoint's identity compared as recorded (a user's file hashed again, one the run did not read
left out) by :meth:`DAggerCheckpoint._check_code`, not as settings."""

_PROGRESS_FIELDS = {"identity": dict, "iteration": int, "history": list, "rng": dict, "envs": list}
"""What every ``progress.json`` holds (:meth:`DAggerCheckpoint.save` and ``save_partial`` write them all)."""


def _progress_problem(data: Any) -> Optional[str]:
    """What is wrong with a read ``progress.json``, or ``None``."""
    schema = data.get("schema") if isinstance(data, dict) else None
    if schema != SCHEMA:
        return f"schema {schema!r}, not {SCHEMA!r}"
    wrong = [name for name, kind in _PROGRESS_FIELDS.items()
             if not isinstance(data.get(name), kind) or isinstance(data.get(name), bool)]
    return f"no valid {', '.join(wrong)}" if wrong else None


def describe_position(iteration: int, rows: int, iterations: int) -> str:
    """``"iteration 2 of 4"`` or ``"iteration 2 of 4 (+1200 steps of iteration 3)"``: where a run resumes."""
    text = f"iteration {iteration} of {iterations}"
    return text + (f" (+{rows} steps of iteration {iteration + 1})" if rows else "")
