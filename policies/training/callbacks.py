"""The stable-baselines3 callbacks of a training run: the curriculum's updates, the periodic held-out
evaluation, the checkpoints, the progress bar."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from tqdm import tqdm

from policies.evaluation import make_eval_env, run_episode
from policies.model_card import summarize_results
from policies.registry import SB3Policy
from policies.training.run_record import step_checkpoints
from policies.training.scenario_envs import ScenarioSampler
from scenario_bank.atomic import atomic_path, atomic_write_json

__all__ = ["CurriculumCallback", "HeldOutEvaluationCallback", "CheckpointSaver", "ProgressCallback"]


def _episode_failed(info: Mapping[str, Any]) -> bool:
    return bool(info.get("crashed") or info.get("collisions") or info.get("off_road"))


class CurriculumCallback(BaseCallback):
    """Feeds finished training episodes to the sampler and sends its probabilities to the workers.

    Every ``update_every`` env steps: ``env_method("set_scenario_probabilities", p)``
    (curriculum only) and TensorBoard scalars ``curriculum/p_<scenario>`` and
    ``train/failure_rate`` (over the episodes finished since the last update).
    """

    def __init__(self, sampler: ScenarioSampler, update_every: int = 1000) -> None:
        super().__init__()
        self.sampler = sampler
        self.update_every = int(update_every)
        self._last = 0
        self._finished: List[bool] = []

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        for done, info in zip(self.locals.get("dones", []), self.locals.get("infos", [])):
            if done and "scenario" in info:
                failed = _episode_failed(info)
                self.sampler.record(str(info["scenario"]), failed)
                self._finished.append(failed)
        if self.num_timesteps - self._last >= self.update_every:
            self.update()
        return True

    def update(self) -> Dict[str, float]:
        """Send the current probabilities to the workers and log them."""
        self._last = self.num_timesteps
        probabilities = self.sampler.probabilities()
        if self.sampler.mode == "curriculum":
            self.training_env.env_method("set_scenario_probabilities", probabilities)
        for name, p in probabilities.items():
            self.logger.record(f"curriculum/p_{name}", p)
        if self._finished:
            self.logger.record("train/failure_rate", float(np.mean(self._finished)))
            self._finished = []
        return probabilities

class HeldOutEvaluationCallback(BaseCallback):
    """Every ``every`` env steps, runs the model deterministically on held-out episodes.

    Logs ``eval/collision_rate``, ``eval/success_rate``, ``eval/off_road_rate``,
    ``eval/mean_return`` to TensorBoard and appends a line to ``log_path`` (JSON lines).
    """

    def __init__(self, episodes: Sequence[Tuple[str, int]], env_config: Mapping[str, Any],
                 bank_dir: Optional[str], every: int, log_path: Path) -> None:
        super().__init__()
        self.episodes = list(episodes)
        self.env_config = dict(env_config)
        self.bank_dir = bank_dir
        self.every = int(every)
        self.log_path = Path(log_path)
        self._last = 0
        self._env = None
        self.latest: Optional[Dict[str, Any]] = None

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every > 0 and self.episodes and self.num_timesteps - self._last >= self.every:
            self.run()
        return True

    def run(self) -> Dict[str, Any]:
        """Evaluate now; returns the overall rates."""
        self._last = self.num_timesteps
        if self._env is None:
            self._env = make_eval_env(sorted({s for s, _ in self.episodes}), config=self.env_config,
                                      bank_dir=self.bank_dir)
        policy = SB3Policy("training", self.model)
        policy.bind([self._env])
        results = [run_episode(self._env, policy, scenario, seed)[0] for scenario, seed in self.episodes]
        overall = summarize_results(results).overall
        for measure in ("collision", "success", "off_road"):
            self.logger.record(f"eval/{measure}_rate", overall.measure(measure)["rate"])
        self.logger.record("eval/mean_return", overall.mean_return)
        self.latest = {"step": int(self.num_timesteps), "episodes": len(results),
                       **{m: overall.measure(m) for m in ("collision", "success", "off_road", "failure")},
                       "mean_return": overall.mean_return}
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.log_path, "a", encoding="utf-8") as handle:
            handle.write(json.dumps(self.latest, sort_keys=True) + "\n")
        return self.latest

    def _on_training_end(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None

class CheckpointSaver(BaseCallback):
    """Saves ``checkpoints/step_<n>.zip`` (atomic) every ``every`` env steps with the sampler's
    state and, for off-policy algorithms, the replay buffer; keeps the newest ``keep``."""

    def __init__(self, directory: Path, every: int, sampler: ScenarioSampler, keep: int = 3) -> None:
        super().__init__()
        self.directory = Path(directory)
        self.every = int(every)
        self.sampler = sampler
        self.keep = int(keep)
        self._last = 0

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every > 0 and self.num_timesteps - self._last >= self.every:
            self.save()
        return True

    def save(self, model: Optional[Any] = None) -> Path:
        """Write a checkpoint of ``model`` (default: the model this callback is attached to) at its
        current step now; returns its path. ``model`` serves a run interrupted before SB3 attached
        the callbacks."""
        model = model if model is not None else self.model
        steps = int(model.num_timesteps)
        self._last = steps
        path = self.directory / f"step_{steps:09d}.zip"
        with atomic_path(path, keep_suffix=True) as tmp:
            model.save(tmp)
        atomic_write_json(path.with_suffix(".sampler.json"), self.sampler.state_dict())
        if getattr(model, "replay_buffer", None) is not None:
            with atomic_path(path.with_suffix(".replay.pkl"), keep_suffix=True) as tmp:
                model.save_replay_buffer(tmp)
        for old in step_checkpoints(self.directory)[:-self.keep]:
            for companion in (old, old.with_suffix(".sampler.json"), old.with_suffix(".replay.pkl")):
                companion.unlink(missing_ok=True)
        return path

class ProgressCallback(BaseCallback):
    """A tqdm bar over the run's whole step budget (a resumed run starts where it stopped)."""

    def __init__(self, total: int, description: str, evaluation: Optional[Any] = None) -> None:
        super().__init__()
        self.total = int(total)
        self.description = description
        self.evaluation = evaluation
        self.bar = None
        self._shown = None

    def _on_training_start(self) -> None:
        self.bar = tqdm(total=self.total, initial=self.num_timesteps, unit="step", desc=self.description,
                        dynamic_ncols=True, smoothing=0.05)

    def _on_step(self) -> bool:
        if self.num_timesteps > self.bar.total:  # the last rollout may overshoot the budget
            self.bar.total = self.num_timesteps
        self.bar.update(self.num_timesteps - self.bar.n)
        latest = getattr(self.evaluation, "latest", None)
        if latest is not None and latest is not self._shown:
            self._shown = latest
            self.bar.set_postfix(collision=f"{latest['collision']['rate']:.2f}",
                                 success=f"{latest['success']['rate']:.2f}")
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
