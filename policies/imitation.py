"""Fine-tuning a stable-baselines3 policy by imitating a reference driver on its own states (DAgger).

The loop's reference driver (``rule``, :class:`~policies.rule_based.CautiousDriver`) reads the
simulator state and, by the miner's avoidability rule, avoids every avoidable mined failure. It
acts in the same ``DiscreteMetaAction`` space as the SB3 policies, so it can label any state
the policy visits with the action it would take there. :func:`dagger_fine_tune` runs DAgger
(Ross, Gordon & Bagnell 2011) on that:

1. iteration ``i`` (of ``iterations``) collects ``steps / iterations`` env steps in ``n_envs``
   training envs (:func:`policies.training.make_vec_env`'s scenario schedule: each episode's
   scenario drawn by ``weights``, reset seeds >= :data:`~policies.evaluation.TRAIN_SEED_LOW`, so no
   evaluation scene is ever visited). At every step the executed action is the reference's
   with probability ``beta_i = beta * beta_decay ** i`` and the current policy's greedy action
   otherwise (:class:`ReferenceLabels`, in the env workers); every visited observation is
   labelled with the reference's action for that state;
2. the labelled states are added to the aggregated data set, and the policy's action
   distribution is trained on all of it by cross-entropy (``policy.get_distribution``, Adam,
   ``epochs`` passes per iteration, minibatches of ``batch_size``). The value network is not
   trained. The cross-entropy is a weighted mean: the reference's SLOWER labels weigh
   ``slower_weight``, and the states where the student that collected them chose greedily
   another action than the label weigh ``disagreement_weight`` (the two multiply).

The result is a normal SB3 checkpoint (``out/model.zip``, the source's class and spaces) with
a model card (``model_card.json``, ``README.md``) whose ``fine_tune`` section has
``method: "dagger"`` and the agreement with the reference (share of labelled states where the
greedy action equals the label) of the source and of the result on the same states.

A run is resumable: each finished iteration is committed to ``out/dagger_checkpoint/``
(:mod:`policies.dagger_checkpoint`), and a killed run called again with the same settings
continues after the last one to the same model and stats as an uninterrupted run.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from policies.dagger_checkpoint import (CHECKPOINT_DIR, DAggerCheckpoint, LabelledBatch, PartialIteration,
                                        describe_position, run_identity)
from policies.state_driver import SLOWER
from policies.dagger_config import DAGGER_DEFAULTS, DaggerConfig
from policies.training import (ScenarioSchedule, TrainConfig, TrainEnvSpec, TrainingError, check_source_observation,
                               close_vec_env, fine_tune_scenarios, make_vec_env, resolve_checkpoint)
from policies.card_record import FineTune, FineTuneMethod, ModelCard
from policies.model_card import write_card
from policies.registry import load_policy, read_model_card
from scenario_bank.atomic import atomic_path
import stable_baselines3 as sb3

__all__ = ["ReferenceLabels", "DAGGER_DEFAULTS", "DaggerConfig", "dagger_fine_tune", "agreement", "imitation_step",
           "loss_weights"]

class ReferenceLabels(gym.Wrapper):
    """Labels every step with the reference driver's action for the state the action is taken in.

    ``step(action)`` asks the reference (a registered state driver, bound to this env) for
    its action in the current state, executes it instead of ``action`` with probability
    ``beta`` (the DAgger mixture) and returns the label in ``info["reference_action"]``
    (and what ran in ``info["executed_action"]``). The label belongs to the observation
    the caller chose ``action`` from, i.e. the one returned by the previous call.
    """

    def __init__(self, env: gym.Env, reference: str = "rule", beta: float = 1.0, seed: int = 0,
                 stream: int = 0) -> None:
        super().__init__(env)

        self.reference = load_policy(reference)
        if not getattr(self.reference, "privileged", False):
            raise TrainingError(f"the DAgger reference must be a driver that reads the simulator state "
                                f"(rule, idm, keep_lane), not {reference!r}")
        self.reference.bind([env])
        self.rng = np.random.default_rng([int(seed), int(stream), 7])
        self.set_beta(beta)

    def set_beta(self, beta: float) -> None:
        """Execute the reference's action with this probability from the next step on."""
        if not 0.0 <= float(beta) <= 1.0:
            raise TrainingError(f"the DAgger mixture beta must be in [0, 1], not {beta}")
        self.beta = float(beta)

    def reset(self, **kwargs: Any):
        schedule = self.env if isinstance(self.env, ScenarioSchedule) else None
        self._episode = {"reset": {k: kwargs[k] for k in ("seed", "options") if kwargs.get(k) is not None},
                         "schedule_rng": None if schedule is None else schedule.rng.bit_generator.state,
                         "actions": []}
        observation, info = self.env.reset(**kwargs)
        self.reference.reset(0)
        self._observation = observation
        return observation, info

    def step(self, action: Any):
        label = int(self.reference.act(np.asarray(self._observation)[None])[0])
        executed = label if self.rng.random() < self.beta else int(np.asarray(action).reshape(-1)[0])
        observation, reward, terminated, truncated, info = self.env.step(executed)
        self._observation = observation
        self._episode["actions"].append(executed)
        info = dict(info)
        info["reference_action"] = label
        info["executed_action"] = executed
        return observation, reward, terminated, truncated, info

    def snapshot(self) -> Dict[str, Any]:
        """Where this env is (JSON-safe): how its current episode was reset (the arguments and the
        scenario schedule's RNG state before it), the actions executed since, the mixture's RNG state
        and ``beta``. :meth:`restore` on a fresh env of the same settings puts it back there."""
        return json.loads(json.dumps({"episode": self._episode, "rng": self.rng.bit_generator.state,
                                      "beta": self.beta}, default=_plain))

    def restore(self, snapshot: Mapping[str, Any]) -> np.ndarray:
        """Put this env where :meth:`snapshot` was taken (same scenario, reset seed and actions, the
        reference asked at every replayed state as in :meth:`step`); returns the current observation.

        The replay costs the current episode's steps, not the run's."""
        episode = snapshot["episode"]
        if episode.get("schedule_rng") is not None and isinstance(self.env, ScenarioSchedule):
            self.env.rng.bit_generator.state = episode["schedule_rng"]
        self.reset(**episode["reset"])
        for action in episode["actions"]:
            self.reference.act(np.asarray(self._observation)[None])
            observation, _, terminated, truncated, _ = self.env.step(int(action))
            if terminated or truncated:
                raise TrainingError("a restored DAgger env ended its episode while replaying it; the env is "
                                    "not deterministic under its reset seed, so the run cannot be resumed")
            self._observation = observation
            self._episode["actions"].append(int(action))
        self.rng.bit_generator.state = snapshot["rng"]
        self.set_beta(snapshot["beta"])
        return self._observation


def _plain(value: Any) -> Any:
    """JSON for numpy scalars (a reset seed handed over as ``np.int64``)."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _as_json(value: Any) -> Any:
    """``value`` as the JSON it is written as (tuples as lists; a value JSON does not know is refused)."""
    return json.loads(json.dumps(value))


def _with_labels(env: gym.Env, seed: int, stream: int, reference: str) -> gym.Env:
    """The training env's outer wrapper in DAgger (``make_vec_env``'s ``wrap``)."""
    return ReferenceLabels(env, reference=reference, seed=seed, stream=stream)


def _greedy(model: Any, observations: np.ndarray, batch: int = 4096) -> np.ndarray:
    """``model``'s greedy action for each of ``observations``."""
    actions = [np.asarray(model.predict(observations[start:start + batch], deterministic=True)[0]).reshape(-1)
               for start in range(0, len(observations), batch)]
    return np.concatenate(actions) if actions else np.zeros(0, dtype=np.int64)


def agreement(model: Any, observations: np.ndarray, labels: np.ndarray, batch: int = 4096) -> float:
    """Share of ``observations`` where ``model``'s greedy action equals ``labels`` (NaN when empty)."""
    if len(labels) == 0:
        return float("nan")
    return int(np.sum(_greedy(model, observations, batch) == labels)) / len(labels)


def imitation_step(model: Any, optimizer: Any, observations: np.ndarray, labels: np.ndarray,
                   weights: Optional[np.ndarray] = None) -> float:
    """One cross-entropy step of ``model``'s action distribution toward ``labels``; returns the loss.

    The loss is the mean of the states' cross-entropies weighted by ``weights`` (``None``: all 1;
    :func:`loss_weights` gives DAgger's).
    """
    import torch

    policy = model.policy
    obs = torch.as_tensor(observations, dtype=torch.float32, device=policy.device)
    actions = torch.as_tensor(labels, dtype=torch.long, device=policy.device)
    log_prob = policy.get_distribution(obs).log_prob(actions)
    if weights is None:
        loss = -log_prob.mean()
    else:
        weight = torch.as_tensor(np.asarray(weights), dtype=log_prob.dtype, device=policy.device)
        loss = -(log_prob * weight).sum() / weight.sum()
    optimizer.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(policy.parameters(), 0.5)
    optimizer.step()
    return float(loss.detach())


def _train(model: Any, optimizer: Any, observations: np.ndarray, labels: np.ndarray, epochs: int, batch_size: int,
           rng: np.random.Generator, weights: Optional[np.ndarray] = None) -> float:
    model.policy.set_training_mode(True)
    losses: List[float] = []
    for _ in range(epochs):
        order = rng.permutation(len(labels))
        for start in range(0, len(order), batch_size):
            rows = order[start:start + batch_size]
            losses.append(imitation_step(model, optimizer, observations[rows], labels[rows],
                                         weights=None if weights is None else weights[rows]))
    model.policy.set_training_mode(False)
    return float(np.mean(losses)) if losses else float("nan")


@dataclasses.dataclass
class _Collected:
    """The states one DAgger iteration has labelled so far, in collection order, and its episode counts."""

    observations: List[np.ndarray] = dataclasses.field(default_factory=list)
    labels: List[np.ndarray] = dataclasses.field(default_factory=list)
    episodes: int = 0
    crashes: int = 0

    @property
    def rows(self) -> int:
        return int(sum(len(chunk) for chunk in self.labels))


def _collect(venv: Any, model: Any, obs: np.ndarray, budget: int, collected: _Collected, every: int,
             commit: Callable[[np.ndarray], None], bar: Any) -> np.ndarray:
    """Step ``venv`` with ``model``'s greedy actions until ``collected`` holds ``budget`` labelled states
    (the wrapper mixes in the reference); ``commit(obs)`` whenever another ``every`` states are in and
    the iteration is not done. Returns the envs' observations at the end."""
    rows = collected.rows
    while rows < budget:
        actions, _ = model.predict(obs, deterministic=True)
        next_obs, _, dones, infos = venv.step(actions)
        collected.observations.append(np.array(obs, dtype=np.float32, copy=True))
        collected.labels.append(np.array([info["reference_action"] for info in infos], dtype=np.int64))
        for done, info in zip(dones, infos):
            if done:
                collected.episodes += 1
                collected.crashes += bool(info.get("crashed") or info.get("collisions") or info.get("off_road"))
        obs = next_obs
        rows += len(actions)
        if bar is not None:
            bar.update(len(actions))
        if every and rows < budget and rows // every > (rows - len(actions)) // every:
            commit(obs)
    return obs


def loss_weights(labels: np.ndarray, disagreed: np.ndarray, slower_weight: float = 1.0,
                 disagreement_weight: float = 1.0) -> Optional[np.ndarray]:
    """Each labelled state's weight in the imitation loss: ``slower_weight`` if its label is SLOWER, times
    ``disagreement_weight`` if the student that collected it chose greedily another action (``disagreed``), each
    1 otherwise (``None`` when both are 1: the plain mean)."""
    if float(slower_weight) == 1.0 and float(disagreement_weight) == 1.0:
        return None
    return (np.where(np.asarray(labels) == SLOWER, float(slower_weight), 1.0)
            * np.where(np.asarray(disagreed, dtype=bool), float(disagreement_weight), 1.0))


def _restore_envs(venv: Any, snapshots: Sequence[Mapping[str, Any]], expected: np.ndarray):
    """Put each env of ``venv`` back where its snapshot was taken (:meth:`ReferenceLabels.restore`):
    ``(observations, whether they equal the checkpoint's)``."""
    restored = [venv.env_method("restore", snapshot, indices=[rank])[0] for rank, snapshot in enumerate(snapshots)]
    obs = np.stack(restored).astype(expected.dtype)
    return obs, bool(np.array_equal(obs, expected))


def dagger_fine_tune(checkpoint_or_spec: str, config: TrainConfig, dagger: Optional[DaggerConfig] = None, *,
                     log: Callable[[str], None] = print) -> Path:
    """Fine-tune an SB3 checkpoint by DAgger toward a reference driver (module docstring); returns
    ``config.out/model.zip``.

    ``config`` (:meth:`TrainConfig.fine_tuning <policies.training.TrainConfig.fine_tuning>`) says what to train
    on: ``steps`` env steps collected in all (split evenly over the iterations), ``weights`` scenario ->
    sampling weight (the scenarios are ``scenarios``, default every one with a positive weight), ``env_config``
    the env's config (``None``: the checkpoint card's; the reward plays no part), ``seed``, ``n_envs``,
    ``vec_env``, ``progress_bar``. ``dagger`` (:class:`~policies.dagger_config.DaggerConfig`, default its
    defaults) says how to imitate: iterations, the reference's share, epochs, Adam's learning rate, the weight
    of the reference's SLOWER labels and of the states the student disagreed on, how often collected states are
    committed.

    Resumable: every finished iteration is committed to ``out/dagger_checkpoint/``
    (:mod:`policies.dagger_checkpoint`: the labelled states, the weights and Adam's state, the
    RNGs, the envs' positions, the stats), and so are the states collected so far every
    ``checkpoint_every`` env steps (0: only finished iterations). Called again with the same
    ``out`` and settings, it continues from the last commit and ends with the same model and stats as an
    uninterrupted run (the card's ``fine_tune.resumed`` lists the resumes); with other settings it
    raises :class:`~scenario_bank.run_identity.RunIdentityError` naming the differences. Called
    with an ``out`` that already holds the result, it returns at once (the checkpoint is removed
    once the result is written).
    """
    dagger = dagger or DaggerConfig()
    for name, value in (("steps", config.steps), ("n_envs", config.n_envs)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise TrainingError(f"DAgger {name} must be an integer >= 1, not {value!r}")

    model_path = Path(config.out) / "model.zip"
    finished = read_model_card(model_path).fine_tune if model_path.is_file() else None
    if finished is not None and finished.is_dagger:
        return model_path
    run = _DaggerRun(checkpoint_or_spec, config, dagger, log)
    run.restore(run.checkpoint.load())  # refuses a checkpoint of other settings before any work
    if run.start < dagger.iterations:
        run.iterate()
    return run.finish()


class _DaggerRun:
    """One DAgger fine-tuning: its settings, the student, the data aggregated so far and its checkpoint."""

    def __init__(self, spec: str, config: TrainConfig, dagger: DaggerConfig, log: Callable[[str], None]) -> None:
        self.spec, self.config, self.dagger, self.log = spec, config, dagger, log
        self.out = Path(config.out)
        weights, scenarios = fine_tune_scenarios(config.weights, config.scenarios)
        self.scenarios = sorted(scenarios)
        self.probabilities = {name: weights.get(name, 0.0) for name in self.scenarios}
        if sum(self.probabilities.values()) <= 0:
            raise TrainingError("fine-tuning needs at least one scenario with a positive weight")
        algorithm, self.source, self.source_card = resolve_checkpoint(spec)
        if algorithm != "ppo":
            raise TrainingError(f"DAgger fine-tunes an actor-critic policy with an action distribution (ppo), not "
                                f"{algorithm}; use --fine-tune-method ppo")
        self.env_config = dict(self.source_card.env_config or {}) if config.env_config is None \
            else config.env_config
        check_source_observation(self.source_card, self.env_config, spec)
        self.checkpoint = DAggerCheckpoint(self.out / CHECKPOINT_DIR, run_identity(
            source=spec, source_checkpoint=self.source, config=config, dagger=dagger, weights=self.probabilities,
            env_config=self.env_config))
        iterations = dagger.iterations
        self.per_iteration = [config.steps // iterations + (1 if i < config.steps % iterations else 0)
                              for i in range(iterations)]

    def restore(self, saved: Any) -> None:
        """The student, its optimizer and RNGs, and the data so far: fresh, or as ``saved`` (the last commit)."""
        import torch

        torch.manual_seed(int(self.config.seed))
        self.model = sb3.PPO.load(str(self.source), device="cpu")
        self.optimizer = torch.optim.Adam(self.model.policy.parameters(), lr=float(self.dagger.learning_rate))
        self.rng = np.random.default_rng([int(self.config.seed), 11])
        self.observations: List[np.ndarray] = []
        self.labels: List[np.ndarray] = []
        self.disagreed: List[np.ndarray] = []
        self.history: List[Dict[str, Any]] = []
        self.resumes: List[Dict[str, Any]] = []
        self.start, self.spent, self.partial, self.saved = 0, 0.0, None, saved
        self.began = time.perf_counter()
        if saved is None:
            return

        if saved.weights is not None:
            self.model.policy.load_state_dict(saved.weights["policy"])
            self.optimizer.load_state_dict(saved.weights["optimizer"])
            torch.set_rng_state(saved.weights["torch_rng"])
        self.rng.bit_generator.state = saved.rng_state
        self.observations, self.labels, self.history = list(saved.observations), list(saved.labels), list(saved.history)
        self.disagreed = list(saved.disagreed)
        self.resumes, self.start, self.spent = list(saved.resumes), saved.iteration, saved.wall_time_s
        self.partial = saved.partial
        rows = self.partial.rows if self.partial else 0
        self.log(f"DAgger: resumed from {describe_position(self.start, rows, self.dagger.iterations)} "
                 f"({sum(len(x) for x in self.labels) + rows} labelled states from {self.checkpoint.folder})")

    def elapsed(self) -> float:
        """Wall time of the whole run so far, earlier runs included."""
        return self.spent + time.perf_counter() - self.began

    def iterate(self) -> None:
        """Run the iterations not committed yet, in training envs put back where the last commit left them."""

        c, d = self.config, self.dagger
        spec = TrainEnvSpec(self.scenarios, self.env_config, c.bank_dir, self.probabilities,
                            wrap=functools.partial(_with_labels, reference=d.reference))
        venv = make_vec_env(spec, c.n_envs, int(c.seed), vec_env=c.vec_env)
        bar = None
        if c.progress_bar:
            bar = tqdm(total=c.steps, initial=sum(self.per_iteration[:self.start])
                       + (self.partial.rows if self.partial else 0), desc="DAgger fine-tune", unit="step")
        try:
            venv.seed(int(c.seed))
            obs = self._reset(venv)
            for iteration in range(self.start, d.iterations):
                obs = self._iteration(venv, obs, iteration, bar)
        finally:
            close_vec_env(venv)
            if bar is not None:
                bar.close()

    def _reset(self, venv: Any) -> np.ndarray:
        obs = venv.reset()
        saved, partial = self.saved, self.partial
        if saved is not None and (partial is not None or self.start > 0):  # the envs back where they were
            obs, reproduced = _restore_envs(venv, *((partial.envs, partial.next_observations) if partial
                                                    else (saved.envs, saved.next_observations)))
            self.resumes.append({"from_iteration": self.start, "steps_into_next": partial.rows if partial else 0,
                                 "envs_reproduced": reproduced})
            if not reproduced:
                self.log("DAgger: warning: the restored envs do not show the checkpoint's observations (the env is "
                         "not deterministic); the result may differ from an uninterrupted run")
        return obs

    def _iteration(self, venv: Any, obs: np.ndarray, iteration: int, bar: Any) -> np.ndarray:
        """Collect iteration ``iteration``'s labelled states, train on everything so far, commit; the envs'
        observations at the end."""
        d, partial = self.dagger, self.partial
        mixture = float(d.beta) * float(d.beta_decay) ** iteration
        venv.env_method("set_beta", mixture)
        collected = _Collected()
        if partial is not None and partial.iteration == iteration + 1:
            collected = _Collected([partial.observations], [partial.labels], partial.episodes, partial.crashes)

        def commit_partial(now: np.ndarray, number: int = iteration + 1, so_far: _Collected = collected):
            self.checkpoint.save_partial(
                PartialIteration(iteration=number, observations=np.concatenate(so_far.observations),
                                 labels=np.concatenate(so_far.labels), next_observations=np.asarray(now),
                                 episodes=so_far.episodes, crashes=so_far.crashes, envs=venv.env_method("snapshot")),
                rng=self.rng, resumes=self.resumes, wall_time_s=self.elapsed())

        obs = _collect(venv, self.model, obs, self.per_iteration[iteration], collected, d.checkpoint_every,
                       commit_partial, bar)
        batch_obs, batch_labels = np.concatenate(collected.observations), np.concatenate(collected.labels)
        disagreed = _greedy(self.model, batch_obs) != batch_labels  # the student that collected them
        on_policy = float(np.mean(~disagreed)) if len(disagreed) else float("nan")
        self.observations.append(batch_obs)
        self.labels.append(batch_labels)
        self.disagreed.append(disagreed)
        all_obs, all_labels = np.concatenate(self.observations), np.concatenate(self.labels)
        loss = _train(self.model, self.optimizer, all_obs, all_labels, d.epochs, d.batch_size, self.rng,
                      loss_weights(all_labels, np.concatenate(self.disagreed), d.slower_weight, d.disagreement_weight))
        record = {"iteration": iteration + 1, "beta": mixture, "steps": int(len(batch_labels)),
                  "episodes_finished": collected.episodes, "episodes_failed": collected.crashes,
                  "agreement_before": round(on_policy, 4),
                  "agreement_after": round(agreement(self.model, batch_obs, batch_labels), 4),
                  "dataset": int(len(all_labels)), "loss": round(loss, 4)}
        self.history.append(record)
        self.checkpoint.save(LabelledBatch(iteration + 1, batch_obs, batch_labels, np.asarray(obs), disagreed),
                             model=self.model, optimizer=self.optimizer, rng=self.rng, history=self.history,
                             envs=venv.env_method("snapshot"), wall_time_s=self.elapsed(), resumes=self.resumes)
        self.log(f"DAgger iteration {iteration + 1}/{d.iterations}: beta {mixture:.3g}, {record['steps']} labelled "
                 f"steps, agreement with {d.reference} {on_policy:.3f} -> {record['agreement_after']:.3f}, "
                 f"{collected.crashes}/{collected.episodes} finished episodes crashed or left the road")
        return obs

    def finish(self) -> Path:
        """Write the fine-tuned model and its card, remove the checkpoint; the model's path."""
        wall = self.elapsed()
        all_obs, all_labels = np.concatenate(self.observations), np.concatenate(self.labels)
        source_model = sb3.PPO.load(str(self.source), device="cpu")
        self.out.mkdir(parents=True, exist_ok=True)
        model_path = self.out / "model.zip"
        with atomic_path(model_path, keep_suffix=True) as tmp:
            self.model.save(tmp)
        card = self._card(wall, {"source": round(agreement(source_model, all_obs, all_labels), 4),
                                 "fine_tuned": round(agreement(self.model, all_obs, all_labels), 4),
                                 "states": int(len(all_labels))})
        write_card(self.out, card)
        self.checkpoint.remove()
        self.log(f"wrote {model_path} (DAgger, agreement with {self.dagger.reference} on {len(all_labels)} labelled "
                 f"states: {card.fine_tune.agreement['source']:.3f} -> "
                 f"{card.fine_tune.agreement['fine_tuned']:.3f})")
        return model_path

    def _card(self, wall: float, agreements: Dict[str, Any]) -> ModelCard:
        c, d, steps = self.config, self.dagger, self.config.steps
        source = self.source_card
        training = {**dict(source.training or {}), "command": "dv2s loop --fine-tune-method dagger",
                    "steps": int(steps), "n_envs": c.n_envs, "seed": int(c.seed), "wall_time_s": round(wall, 1),
                    "steps_per_s": round(steps / wall, 1) if wall > 0 else None, "segments": []}
        fine_tune = FineTune.from_dict(_as_json({
            "method": FineTuneMethod.DAGGER.value, "source": str(self.spec), "source_checkpoint": str(self.source),
            "steps": int(steps), "weights": self.probabilities, "learning_rate": float(d.learning_rate),
            "reference": d.reference, "iterations": d.iterations, "beta": float(d.beta),
            "beta_decay": float(d.beta_decay), "epochs": d.epochs, "batch_size": d.batch_size,
            "slower_weight": float(d.slower_weight), "disagreement_weight": float(d.disagreement_weight),
            "history": self.history, "agreement": agreements, "resumed": self.resumes}))
        description = (f"Fine-tuned from {self.spec} by DAgger toward the {d.reference} driver: {steps} "
                       f"labelled env steps in {d.iterations} iterations on {len(self.scenarios)} scenarios "
                       "with weighted sampling (see fine_tune).")
        return source.replace(
            evaluation=None, null_fields=(source.null_fields or frozenset()) - {"evaluation"},
            env_config=_as_json(dict(self.env_config)),
            sampler=_as_json({"mode": "weighted", "weights": self.probabilities}), training=_as_json(training),
            fine_tune=fine_tune, description=description, name=self.out.name)
