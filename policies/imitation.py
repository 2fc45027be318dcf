"""Fine-tuning a stable-baselines3 policy by imitating a reference driver on its own states (DAgger).

The loop's reference driver (``rule``, :class:`~policies.rule_based.CautiousDriver`) reads the
simulator state and, by the miner's avoidability rule, avoids every avoidable mined failure. It
acts in the same ``DiscreteMetaAction`` space as the SB3 policies, so it can label any state
the policy visits with the action it would take there. :func:`dagger_fine_tune` runs DAgger
(Ross, Gordon & Bagnell 2011) on that:

1. iteration ``i`` (of ``iterations``) collects ``steps / iterations`` env steps in ``n_envs``
   training envs (:func:`policies.training.make_vec_env`'s scenario schedule: each episode's
   scenario drawn by ``weights``, reset seeds >= :data:`~policies.training.TRAIN_SEED_LOW`, so no
   evaluation scene is ever visited). At every step the executed action is the reference's
   with probability ``beta_i = beta * beta_decay ** i`` and the current policy's greedy action
   otherwise (:class:`ReferenceLabels`, in the env workers); every visited observation is
   labelled with the reference's action for that state;
2. the labelled states are added to the aggregated data set, and the policy's action
   distribution is trained on all of it by cross-entropy (``policy.get_distribution``, Adam,
   ``epochs`` passes per iteration, minibatches of ``batch_size``). The value network is not
   trained.

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
import os
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

import gymnasium as gym
import numpy as np

from policies.state_driver import SLOWER
from policies.training import ScenarioSchedule, TrainingError, fine_tune_scenarios

__all__ = ["ReferenceLabels", "DAGGER_DEFAULTS", "dagger_fine_tune", "agreement", "imitation_step"]

DAGGER_DEFAULTS: Dict[str, Any] = {"iterations": 4, "beta": 1.0, "beta_decay": 0.5, "epochs": 8,
                                   "batch_size": 256, "learning_rate": 1e-3, "reference": "rule", "slower_weight": 3.0}
"""DAgger's settings when not given: 4 iterations, the reference drives the first one alone
(beta 1) and half as often in each next one (0.5, 0.25, 0.125), 8 epochs over the aggregated
data per iteration in minibatches of 256 with Adam at 1e-3, the ``rule`` driver as the
reference, its SLOWER labels weighted 3x in the cross-entropy. Chosen on the seed-0 loop round in
bench/RESULTS.md (4 epochs at 1e-4 underfit: agreement 0.69 and a bank regression; 8 at 1e-3:
agreement 0.86). SLOWER is a rare label that decides episodes (the student rolled on where the
reference braked for crossing pedestrians); unweighted, the 252-pair bank test failed, weighted 3x it
passed on seeds 0 and 1."""


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
        from policies.registry import load_policy

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


def _with_labels(env: gym.Env, seed: int, stream: int, reference: str) -> gym.Env:
    """The training env's outer wrapper in DAgger (``make_vec_env``'s ``wrap``)."""
    return ReferenceLabels(env, reference=reference, seed=seed, stream=stream)


def agreement(model: Any, observations: np.ndarray, labels: np.ndarray, batch: int = 4096) -> float:
    """Share of ``observations`` where ``model``'s greedy action equals ``labels`` (NaN when empty)."""
    if len(labels) == 0:
        return float("nan")
    hits = 0
    for start in range(0, len(labels), batch):
        actions, _ = model.predict(observations[start:start + batch], deterministic=True)
        hits += int(np.sum(np.asarray(actions).reshape(-1) == labels[start:start + batch]))
    return hits / len(labels)


def imitation_step(model: Any, optimizer: Any, observations: np.ndarray, labels: np.ndarray,
                   slower_weight: float = 1.0) -> float:
    """One cross-entropy step of ``model``'s action distribution toward ``labels``; returns the loss.

    ``slower_weight``: weight of the SLOWER labels in the (weighted mean) cross-entropy, the others 1.
    """
    import torch

    policy = model.policy
    obs = torch.as_tensor(observations, dtype=torch.float32, device=policy.device)
    actions = torch.as_tensor(labels, dtype=torch.long, device=policy.device)
    log_prob = policy.get_distribution(obs).log_prob(actions)
    if slower_weight == 1.0:
        loss = -log_prob.mean()
    else:
        weights = torch.where(actions == SLOWER, float(slower_weight), 1.0).to(log_prob.dtype)
        loss = -(log_prob * weights).sum() / weights.sum()
    optimizer.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(policy.parameters(), 0.5)
    optimizer.step()
    return float(loss.detach())


def _train(model: Any, optimizer: Any, observations: np.ndarray, labels: np.ndarray, epochs: int, batch_size: int,
           rng: np.random.Generator, slower_weight: float = 1.0) -> float:
    model.policy.set_training_mode(True)
    losses: List[float] = []
    for _ in range(epochs):
        order = rng.permutation(len(labels))
        for start in range(0, len(order), batch_size):
            rows = order[start:start + batch_size]
            losses.append(imitation_step(model, optimizer, observations[rows], labels[rows], slower_weight))
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


def _restore_envs(venv: Any, snapshots: Sequence[Mapping[str, Any]], expected: np.ndarray):
    """Put each env of ``venv`` back where its snapshot was taken (:meth:`ReferenceLabels.restore`):
    ``(observations, whether they equal the checkpoint's)``."""
    restored = [venv.env_method("restore", snapshot, indices=[rank])[0] for rank, snapshot in enumerate(snapshots)]
    obs = np.stack(restored).astype(expected.dtype)
    return obs, bool(np.array_equal(obs, expected))


def dagger_fine_tune(checkpoint_or_spec: str, *, bank_dir: Optional[str], out: os.PathLike | str, steps: int,
                     weights: Mapping[str, float], seed: int = 0, n_envs: int = 2,
                     scenarios: Optional[Sequence[str]] = None, env_config: Optional[Dict[str, Any]] = None,
                     learning_rate: Optional[float] = None, iterations: int = DAGGER_DEFAULTS["iterations"],
                     beta: float = DAGGER_DEFAULTS["beta"], beta_decay: float = DAGGER_DEFAULTS["beta_decay"],
                     epochs: int = DAGGER_DEFAULTS["epochs"], batch_size: int = DAGGER_DEFAULTS["batch_size"],
                     reference: str = DAGGER_DEFAULTS["reference"],
                     slower_weight: float = DAGGER_DEFAULTS["slower_weight"], vec_env: str = "subproc",
                     progress_bar: bool = True, log: Callable[[str], None] = print,
                     checkpoint_every: int = 2000) -> Path:
    """Fine-tune an SB3 checkpoint by DAgger toward ``reference`` (module docstring); returns ``out/model.zip``.

    ``steps``: env steps collected in all (split evenly over ``iterations``); ``weights``:
    scenario -> sampling weight (the scenarios are ``scenarios``, default every one with a
    positive weight); ``env_config``: the env's config (default the checkpoint card's; the
    reward plays no part); ``learning_rate``: Adam's (default ``DAGGER_DEFAULTS["learning_rate"]``);
    ``slower_weight``: weight of the reference's SLOWER labels in the cross-entropy (1: unweighted).

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
    for name, value, low in (("steps", steps, 1), ("iterations", iterations, 1), ("epochs", epochs, 0),
                             ("batch_size", batch_size, 1), ("n_envs", n_envs, 1),
                             ("checkpoint_every", checkpoint_every, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise TrainingError(f"DAgger {name} must be an integer >= {low}, not {value!r}")
    if not 0.0 <= float(beta) <= 1.0 or not 0.0 <= float(beta_decay) <= 1.0:
        raise TrainingError(f"DAgger beta and beta_decay must be in [0, 1], not {beta} and {beta_decay}")
    if isinstance(slower_weight, bool) or not isinstance(slower_weight, (int, float)) or not slower_weight > 0:
        raise TrainingError(f"DAgger slower_weight must be a number > 0, not {slower_weight!r}")
    from policies.dagger_checkpoint import CHECKPOINT_DIR, DAggerCheckpoint, describe_position, run_identity
    from policies.model_card import write_card
    from policies.registry import read_model_card
    from policies.training import resolve_checkpoint
    from scenario_bank.atomic import atomic_path

    out = Path(out)
    model_path = out / "model.zip"
    if model_path.is_file() and (read_model_card(model_path).get("fine_tune") or {}).get("method") == "dagger":
        return model_path
    weights, scenarios = fine_tune_scenarios(weights, scenarios)
    scenarios = sorted(scenarios)
    probabilities = {name: weights.get(name, 0.0) for name in scenarios}
    if sum(probabilities.values()) <= 0:
        raise TrainingError("fine-tuning needs at least one scenario with a positive weight")
    algorithm, source, source_card = resolve_checkpoint(checkpoint_or_spec)
    if algorithm != "ppo":
        raise TrainingError(f"DAgger fine-tunes an actor-critic policy with an action distribution (ppo), not "
                            f"{algorithm}; use --fine-tune-method ppo")
    if env_config is None:
        env_config = dict(source_card.get("env_config") or {})
    lr = DAGGER_DEFAULTS["learning_rate"] if learning_rate is None else float(learning_rate)
    checkpoint = DAggerCheckpoint(out / CHECKPOINT_DIR, run_identity(
        source=checkpoint_or_spec, source_checkpoint=source, bank_dir=bank_dir, weights=probabilities,
        env_config=env_config, steps=steps, iterations=iterations, beta=beta, beta_decay=beta_decay, epochs=epochs,
        batch_size=batch_size, learning_rate=lr, reference=reference, seed=int(seed), n_envs=n_envs,
        slower_weight=float(slower_weight)))
    saved = checkpoint.load()  # refuses a checkpoint of other settings before any work
    import stable_baselines3 as sb3
    import torch

    torch.manual_seed(int(seed))
    model = sb3.PPO.load(str(source), device="cpu")
    optimizer = torch.optim.Adam(model.policy.parameters(), lr=lr)
    rng = np.random.default_rng([int(seed), 11])
    per_iteration = [steps // iterations + (1 if i < steps % iterations else 0) for i in range(iterations)]
    observations: List[np.ndarray] = []
    labels: List[np.ndarray] = []
    history: List[Dict[str, Any]] = []
    resumes: List[Dict[str, Any]] = []
    start, spent, partial = 0, 0.0, None
    if saved is not None:
        if saved.weights is not None:
            model.policy.load_state_dict(saved.weights["policy"])
            optimizer.load_state_dict(saved.weights["optimizer"])
            torch.set_rng_state(saved.weights["torch_rng"])
        rng.bit_generator.state = saved.rng_state
        observations, labels, history = list(saved.observations), list(saved.labels), list(saved.history)
        resumes, start, spent, partial = list(saved.resumes), saved.iteration, saved.wall_time_s, saved.partial
        log(f"DAgger: resumed from {describe_position(start, partial.rows if partial else 0, iterations)} "
            f"({sum(len(x) for x in labels) + (partial.rows if partial else 0)} labelled states from "
            f"{checkpoint.folder})")
    began = time.perf_counter()
    if start < iterations:
        from policies.training import make_vec_env

        venv = make_vec_env(scenarios, env_config, bank_dir, probabilities, n_envs, int(seed), vec_env=vec_env,
                            wrap=functools.partial(_with_labels, reference=reference))
        bar = None
        if progress_bar:
            from tqdm import tqdm

            bar = tqdm(total=steps, initial=sum(per_iteration[:start]) + (partial.rows if partial else 0),
                       desc="DAgger fine-tune", unit="step")
        try:
            venv.seed(int(seed))
            obs = venv.reset()
            if saved is not None and (partial is not None or start > 0):  # the envs back where they were
                obs, reproduced = _restore_envs(venv, *((partial.envs, partial.next_observations) if partial
                                                        else (saved.envs, saved.next_observations)))
                resumes.append({"from_iteration": start, "steps_into_next": partial.rows if partial else 0,
                                "envs_reproduced": reproduced})
                if not reproduced:
                    log("DAgger: warning: the restored envs do not show the checkpoint's observations (the env is "
                        "not deterministic); the result may differ from an uninterrupted run")
            for iteration in range(start, iterations):
                budget = per_iteration[iteration]
                mixture = float(beta) * float(beta_decay) ** iteration
                venv.env_method("set_beta", mixture)
                collected = _Collected()
                if partial is not None and partial.iteration == iteration + 1:
                    collected = _Collected([partial.observations], [partial.labels], partial.episodes,
                                           partial.crashes)

                def commit_partial(now: np.ndarray, number: int = iteration + 1, so_far: _Collected = collected):
                    checkpoint.save_partial(
                        iteration=number, observations=np.concatenate(so_far.observations),
                        labels=np.concatenate(so_far.labels), next_observations=np.asarray(now),
                        episodes=so_far.episodes, crashes=so_far.crashes, envs=venv.env_method("snapshot"), rng=rng,
                        resumes=resumes, wall_time_s=spent + time.perf_counter() - began)

                obs = _collect(venv, model, obs, budget, collected, checkpoint_every, commit_partial, bar)
                batch_obs = np.concatenate(collected.observations)
                batch_labels = np.concatenate(collected.labels)
                episodes, crashes = collected.episodes, collected.crashes
                on_policy = agreement(model, batch_obs, batch_labels)
                observations.append(batch_obs)
                labels.append(batch_labels)
                all_obs, all_labels = np.concatenate(observations), np.concatenate(labels)
                loss = _train(model, optimizer, all_obs, all_labels, epochs, batch_size, rng, float(slower_weight))
                record = {"iteration": iteration + 1, "beta": mixture, "steps": int(len(batch_labels)),
                          "episodes_finished": episodes, "episodes_failed": crashes,
                          "agreement_before": round(on_policy, 4),
                          "agreement_after": round(agreement(model, batch_obs, batch_labels), 4),
                          "dataset": int(len(all_labels)), "loss": round(loss, 4)}
                history.append(record)
                checkpoint.save(iteration=iteration + 1, observations=batch_obs, labels=batch_labels,
                                next_observations=np.asarray(obs), model=model, optimizer=optimizer, rng=rng,
                                history=history, envs=venv.env_method("snapshot"),
                                wall_time_s=spent + time.perf_counter() - began, resumes=resumes)
                log(f"DAgger iteration {iteration + 1}/{iterations}: beta {mixture:.3g}, {record['steps']} labelled "
                    f"steps, agreement with {reference} {on_policy:.3f} -> {record['agreement_after']:.3f}, "
                    f"{crashes}/{episodes} finished episodes crashed or left the road")
        finally:
            venv.close()
            if bar is not None:
                bar.close()
    wall = spent + time.perf_counter() - began
    all_obs, all_labels = np.concatenate(observations), np.concatenate(labels)
    source_model = sb3.PPO.load(str(source), device="cpu")
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(model_path, keep_suffix=True) as tmp:
        model.save(tmp)
    card = json.loads(json.dumps({k: v for k, v in source_card.items() if k != "evaluation"}))
    card["env_config"] = dict(env_config)
    card["sampler"] = {"mode": "weighted", "weights": probabilities}
    card["training"] = {**dict(card.get("training") or {}), "command": "dv2s loop --fine-tune-method dagger",
                        "steps": int(steps), "n_envs": n_envs, "seed": int(seed), "wall_time_s": round(wall, 1),
                        "steps_per_s": round(steps / wall, 1) if wall > 0 else None, "segments": []}
    card["fine_tune"] = {"method": "dagger", "source": str(checkpoint_or_spec), "source_checkpoint": str(source),
                         "steps": int(steps), "weights": probabilities, "learning_rate": lr, "reference": reference,
                         "iterations": iterations, "beta": float(beta), "beta_decay": float(beta_decay),
                         "epochs": epochs, "batch_size": batch_size, "slower_weight": float(slower_weight),
                         "history": history,
                         "agreement": {"source": round(agreement(source_model, all_obs, all_labels), 4),
                                       "fine_tuned": round(agreement(model, all_obs, all_labels), 4),
                                       "states": int(len(all_labels))},
                         "resumed": resumes}
    card["description"] = (f"Fine-tuned from {checkpoint_or_spec} by DAgger toward the {reference} driver: {steps} "
                           f"labelled env steps in {iterations} iterations on {len(scenarios)} scenarios with "
                           "weighted sampling (see fine_tune).")
    card["name"] = out.name
    write_card(out, card)
    checkpoint.remove()
    log(f"wrote {model_path} (DAgger, agreement with {reference} on {len(all_labels)} labelled states: "
        f"{card['fine_tune']['agreement']['source']:.3f} -> {card['fine_tune']['agreement']['fine_tuned']:.3f})")
    return model_path
