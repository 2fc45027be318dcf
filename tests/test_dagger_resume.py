"""Resuming a killed DAgger run (`policies.dagger_checkpoint`): the envs put back where they were, the run
continued from its last committed iteration to the same model and stats as an uninterrupted one, a
checkpoint of other settings refused."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import torch

import policies.imitation as imitation
from scenario_bank.run_identity import RunIdentityError
from envs.dv2s_env import DV2SEnv
from policies.dagger_checkpoint import CHECKPOINT_DIR, DAggerCheckpoint, DAggerResumeError
from policies.imitation import ReferenceLabels
from fine_tune_helpers import dagger_fine_tune
from policies.model_card import read_card
from policies.registry import SHIPPED_CHECKPOINT, load_policy
from policies.training import ScenarioSchedule

SOURCES = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
WEIGHTS = {SOURCES[0]: 1.0, SOURCES[1]: 3.0}
SHIPPED_CONFIG = read_card(SHIPPED_CHECKPOINT).env_config
# 2 iterations of 110 steps in each of 2 envs (episodes: 100 steps at most): iteration 1 ends mid-episode, after
# an episode has ended
RUN = dict(bank_dir=None, steps=440, weights=WEIGHTS, seed=3, n_envs=2, vec_env="dummy", iterations=2, epochs=2,
           batch_size=64, progress_bar=False)


def checkpoint_position(out):
    """``(finished iterations, states labelled in the next one)`` of the DAgger run checkpointed in ``out``, as its
    ``progress.json`` records them."""
    data = json.loads((out / CHECKPOINT_DIR / "progress.json").read_text(encoding="utf-8"))
    return int(data["iteration"]), int((data.get("partial") or {}).get("rows", 0))


def _labelled_env(stream: int = 0) -> ReferenceLabels:
    schedule = ScenarioSchedule(DV2SEnv(scenario=SOURCES, config=dict(SHIPPED_CONFIG)), WEIGHTS, seed=4, stream=stream)
    return ReferenceLabels(schedule, beta=0.5, seed=4, stream=stream)


def _drive(env: ReferenceLabels, model, observation, steps: int):
    """``steps`` greedy steps of ``model`` (resetting when an episode ends): observations, labels, executed."""
    seen = []
    for _ in range(steps):
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(action)
        seen.append((np.asarray(observation).tobytes(), info["reference_action"], info["executed_action"]))
        if terminated or truncated:
            observation, _ = env.reset()
    return seen, observation


@pytest.mark.slow
def test_a_restored_env_continues_exactly_like_the_original():
    model = load_policy("dv2s-ppo").model
    original = _labelled_env()
    observation, _ = original.reset(seed=9)
    for _ in range(200):  # past one episode's end, 10 steps into the next
        if original.snapshot()["episode"]["reset"] == {} and len(original.snapshot()["episode"]["actions"]) == 10:
            break
        _, observation = _drive(original, model, observation, 1)
    snapshot = original.snapshot()
    assert snapshot["episode"]["actions"] and "seed" not in snapshot["episode"]["reset"]  # an auto-reset episode
    expected, _ = _drive(original, model, observation, 40)
    original.close()
    copy = _labelled_env()
    copy.reset(seed=123)  # anywhere else first
    observation = copy.restore(json.loads(json.dumps(snapshot)))
    assert copy.snapshot() == snapshot
    seen, _ = _drive(copy, model, observation, 40)
    copy.close()
    assert seen == expected


def _weights(path):
    return load_policy(f"ppo:{path}").model.policy.state_dict()


def _same_model(a, b) -> None:
    wa, wb = _weights(a), _weights(b)
    assert wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)
    batch = np.random.default_rng(0).uniform(-1, 1, size=(64, *load_policy(f"ppo:{a}").model.observation_space.shape))
    pa = load_policy(f"ppo:{a}").model.policy.get_distribution(torch.as_tensor(batch, dtype=torch.float32))
    pb = load_policy(f"ppo:{b}").model.policy.get_distribution(torch.as_tensor(batch, dtype=torch.float32))
    assert torch.equal(pa.distribution.probs, pb.distribution.probs)


def _stats(path):
    tuned = read_card(path).fine_tune
    return tuned.history, tuned.agreement


def _kill_on_train_call(monkeypatch, call: int) -> None:
    """Make the ``call``-th training of the run raise ``KeyboardInterrupt`` (killed mid-iteration)."""
    original, calls = imitation._train, [0]

    def train(*args, **kwargs):
        calls[0] += 1
        if calls[0] == call:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(imitation, "_train", train)


@pytest.mark.slow
def test_a_killed_dagger_run_resumes_to_the_same_model_and_refuses_other_settings(tmp_path, monkeypatch):
    whole = dagger_fine_tune("dv2s-ppo", out=tmp_path / "whole", log=lambda _: None, **RUN)
    assert list(read_card(whole).fine_tune.resumed) == []
    assert not list((tmp_path / "whole").rglob("partial_*"))  # 220-step iterations, a partial every 2000 steps
    assert not (tmp_path / "whole" / CHECKPOINT_DIR).exists()  # removed once the result is written

    out = tmp_path / "killed"
    _kill_on_train_call(monkeypatch, 2)  # iteration 2 collected, killed while training on it
    with pytest.raises(KeyboardInterrupt):
        dagger_fine_tune("dv2s-ppo", out=out, log=lambda _: None, **RUN)
    monkeypatch.undo()
    assert checkpoint_position(out) == (1, 0) and not (out / "model.zip").exists()
    progress = json.loads((out / CHECKPOINT_DIR / "progress.json").read_text())
    assert progress["history"][0]["episodes_finished"] >= 1  # the schedule moved on before the kill...
    assert all(env["episode"]["actions"] for env in progress["envs"])  # ...and each env is mid-episode

    # other settings: refused before any work, naming the setting and the fix; the checkpoint is untouched
    before = (out / CHECKPOINT_DIR / "progress.json").read_bytes()
    for change, named in (({"learning_rate": 5e-4}, "learning_rate: run has 0.001, asked 0.0005"),
                          ({"steps": 200}, "steps: run has 440"), ({"seed": 4}, "seed: run has 3, asked 4"),
                          ({"weights": {SOURCES[0]: 1.0}}, "weights: run has")):
        with pytest.raises(RunIdentityError, match=named) as error:
            dagger_fine_tune("dv2s-ppo", out=out, log=lambda _: None, **{**RUN, **change})
        assert f"delete {out / CHECKPOINT_DIR}" in str(error.value) and "same settings" in str(error.value)
    assert (out / CHECKPOINT_DIR / "progress.json").read_bytes() == before

    lines = []
    resumed = dagger_fine_tune("dv2s-ppo", out=out, log=lines.append, **RUN)
    assert lines[0].startswith("DAgger: resumed from iteration 1 of 2 (220 labelled states")
    assert [line.split(":")[0] for line in lines[1:2]] == ["DAgger iteration 2/2"]  # iteration 1 not redone
    _same_model(whole, resumed)
    assert _stats(resumed) == _stats(whole)
    assert list(read_card(resumed).fine_tune.resumed) == [{"from_iteration": 1, "steps_into_next": 0,
                                                           "envs_reproduced": True}]
    assert not (out / CHECKPOINT_DIR).exists()


def _kill_at_partial_commit(monkeypatch, out, run: dict, call: int) -> None:
    """Run a DAgger fine-tuning into ``out`` and kill it (KeyboardInterrupt) at its ``call``-th partial commit."""
    original, calls = DAggerCheckpoint.save_partial, [0]

    def save_partial(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] == call:
            raise KeyboardInterrupt
        original(self, *args, **kwargs)

    monkeypatch.setattr(DAggerCheckpoint, "save_partial", save_partial)
    with pytest.raises(KeyboardInterrupt):
        dagger_fine_tune("dv2s-ppo", out=out, log=lambda _: None, **run)
    monkeypatch.undo()


@pytest.mark.slow
@pytest.mark.parametrize("killed_at_call, position", [(3, (0, 120)), (6, (1, 120))])
def test_a_run_killed_while_collecting_resumes_from_its_last_partial_commit(tmp_path, monkeypatch, killed_at_call,
                                                                             position):
    whole = dagger_fine_tune("dv2s-ppo", out=tmp_path / "whole", log=lambda _: None, **RUN)
    run = {**RUN, "checkpoint_every": 60}  # partial commits at 60, 120, 180 steps of each 220-step iteration
    out = tmp_path / "killed"
    _kill_at_partial_commit(monkeypatch, out, run, killed_at_call)  # mid-collection, 60 steps after the last commit
    assert checkpoint_position(out) == position
    assert [p.name for p in (out / CHECKPOINT_DIR).glob("partial_*")] == [f"partial_{position[0] + 1}_120.npz"]
    lines = []
    resumed = dagger_fine_tune("dv2s-ppo", out=out, log=lines.append, **run)
    assert lines[0].startswith(f"DAgger: resumed from iteration {position[0]} of 2 (+120 steps of iteration "
                               f"{position[0] + 1})")
    _same_model(whole, resumed)
    assert _stats(resumed) == _stats(whole)
    assert list(read_card(resumed).fine_tune.resumed) == [{"from_iteration": position[0], "steps_into_next": 120,
                                                           "envs_reproduced": True}]


@pytest.mark.slow
def test_a_run_killed_after_its_last_iteration_only_writes_the_result(tmp_path, monkeypatch):
    run = {**RUN, "steps": 120}
    whole = dagger_fine_tune("dv2s-ppo", out=tmp_path / "whole", log=lambda _: None, **run)
    import policies.imitation as imitation

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(imitation, "write_card", killed)
    with pytest.raises(KeyboardInterrupt):
        dagger_fine_tune("dv2s-ppo", out=tmp_path / "late", log=lambda _: None, **run)
    monkeypatch.undo()
    assert checkpoint_position(tmp_path / "late") == (2, 0)

    def no_envs(*args, **kwargs):
        raise AssertionError("a finished run built training envs")

    monkeypatch.setattr(imitation, "make_vec_env", no_envs)
    resumed = dagger_fine_tune("dv2s-ppo", out=tmp_path / "late", log=lambda _: None, **run)
    _same_model(whole, resumed)
    assert _stats(resumed) == _stats(whole)
    assert list(read_card(resumed).fine_tune.resumed) == []  # no env was restored


def test_an_unreadable_checkpoint_is_refused_with_the_fix(tmp_path):
    folder = tmp_path / "run" / CHECKPOINT_DIR
    folder.mkdir(parents=True)
    (folder / "progress.json").write_text("{not json")
    with pytest.raises(DAggerResumeError, match=f"unreadable .*delete {folder}"):
        dagger_fine_tune("dv2s-ppo", out=tmp_path / "run", log=lambda _: None, **RUN)


_GOOD_PROGRESS = {"schema": "dv2s-dagger-checkpoint", "version": 3, "identity": {}, "iteration": 0,
                  "history": [], "rng": {}, "envs": [], "partial": None}


@pytest.mark.parametrize("text, problem", [
    ("[]", "schema None"),
    ('"dv2s-dagger-checkpoint"', "schema None"),
    (json.dumps({**_GOOD_PROGRESS, "schema": "other"}), "schema 'other'"),
    (json.dumps({key: value for key, value in _GOOD_PROGRESS.items() if key != "iteration"}), "no valid iteration"),
    (json.dumps({**_GOOD_PROGRESS, "iteration": "2", "identity": []}), "no valid identity, iteration"),
    (json.dumps({**_GOOD_PROGRESS, "iteration": True}), "no valid iteration"),
    ("\udcff", "codec can't decode"),
])
def test_a_damaged_progress_file_is_refused_with_the_fix(tmp_path, text, problem):
    """A ``progress.json`` that is JSON but not a checkpoint's (another value, fields missing or of another type)
    is refused as unreadable, naming the fix, instead of failing later with a bare KeyError or AttributeError."""
    folder = tmp_path / CHECKPOINT_DIR
    folder.mkdir()
    (folder / "progress.json").write_bytes(text.encode("utf-8", "surrogateescape"))
    with pytest.raises(DAggerResumeError, match=f"unreadable .*{re.escape(problem)}.*delete {re.escape(str(folder))}"):
        DAggerCheckpoint(folder, {}).load()


def test_a_damaged_partial_record_is_refused_with_the_fix(tmp_path):
    folder = tmp_path / CHECKPOINT_DIR
    folder.mkdir()
    (folder / "progress.json").write_text(json.dumps({**_GOOD_PROGRESS, "partial": "partial_1_10.npz"}))
    with pytest.raises(DAggerResumeError, match=f"incomplete .*delete {re.escape(str(folder))}"):
        DAggerCheckpoint(folder, {}).load()


def test_a_whole_progress_file_with_no_iteration_done_loads(tmp_path):
    folder = tmp_path / CHECKPOINT_DIR
    folder.mkdir()
    (folder / "progress.json").write_text(json.dumps(_GOOD_PROGRESS))
    saved = DAggerCheckpoint(folder, {}).load()
    assert saved.iteration == 0 and saved.observations == [] and saved.partial is None


@pytest.mark.slow
def test_the_loop_resumes_a_killed_dagger_fine_tune_and_says_so(tmp_path, monkeypatch):
    from loop_helpers import run_loop
    from loop_helpers import FakeMiner

    out = tmp_path / "loop"
    miner = FakeMiner(SOURCES, failures_per_round=4)
    tiny = dict(budget=6, fine_tune_steps=200, k_eval=1, regress_episodes=1, workers=1, n_envs=1, progress=False,
                scenarios=SOURCES, fine_tune_method="dagger", control=False, untouched_seeds=0)
    _kill_on_train_call(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        run_loop("dv2s-ppo", out=out, miner=miner, log=lambda _: None, **tiny)
    monkeypatch.undo()
    steps = json.loads((out / "loop.json").read_text())["rounds"][0]["steps"]
    assert "before" in steps and "fine_tune" not in steps
    assert checkpoint_position(out / "round_1" / "policy") == (1, 0)
    lines = []
    report = run_loop("dv2s-ppo", out=out, miner=miner, log=lines.append, **tiny)
    resumed = [line for line in lines if "resumed from iteration 1 of 4" in line]
    assert len(resumed) == 1 and resumed[0].startswith("DAgger: resumed from iteration 1 of 4")  # said once
    assert "DAgger iteration 1/4" not in "\n".join(lines)  # not redone
    tuned = report.rounds[0].to_dict()["steps"]["fine_tune"]
    # subprocess envs put back where they were too
    assert tuned["resumed"] == [{"from_iteration": 1, "steps_into_next": 0, "envs_reproduced": True}]
    assert [h["iteration"] for h in read_card(tuned["model"]).fine_tune.history] == [1, 2, 3, 4]
    assert "resumed from iteration 1:" in report.paths["md"].read_text()
    assert len(miner.calls) == 1  # mining was not redone either
