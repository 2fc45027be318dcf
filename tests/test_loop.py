"""`dv2s loop`: the by-cluster split, fine-tuning from a checkpoint, paired held-out evaluation,
resuming a killed loop without redoing finished steps, and the report of a whole round."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dv2s_gym.mining.heldout import HeldOutStore, evaluate_heldout, paired_summary
from dv2s_gym.mining.loop import LoopError, fine_tune_weights, run_loop
from dv2s_gym.mining.split import cluster_groups, split_by_cluster
from cli_helpers import one_line_error, run
from loop_helpers import FakeMiner
from policies.model_card import read_card
from policies.registry import SHIPPED_CHECKPOINT, load_policy
from policies.training import EVAL_SEED_BASE, TrainingError, fine_tune

SOURCES = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]


# --------------------------------------------------------------------------- split
def _random_entries(rng: np.random.Generator, n: int):
    entries = []
    for i in range(n):
        cluster = f"s{rng.integers(4)}/{['collision', 'off_road'][rng.integers(2)]}/r{rng.integers(6)}"
        scenario = f"mined_{rng.integers(n)}"  # collisions: merged entries tie clusters together
        entries.append({"cluster": cluster, "scenario": scenario})
    return entries


@pytest.mark.parametrize("trial", range(30))
def test_split_never_puts_one_cluster_or_scenario_on_both_sides(trial):
    rng = np.random.default_rng(trial)
    entries = _random_entries(rng, int(rng.integers(2, 25)))
    split = split_by_cluster(entries, fraction=0.5, seed=trial)
    assert not set(split["held_out_clusters"]) & set(split["fine_tune_clusters"])
    assert not set(split["held_out"]) & set(split["fine_tune"])
    assert set(split["held_out_clusters"]) | set(split["fine_tune_clusters"]) == {e["cluster"] for e in entries}
    assert set(split["held_out"]) | set(split["fine_tune"]) == {e["scenario"] for e in entries}
    for entry in entries:  # a scenario sits on the side of its cluster
        side = "held_out" if entry["cluster"] in split["held_out_clusters"] else "fine_tune"
        assert entry["scenario"] in split[side]
    if split["groups"] >= 2:  # both sides get something
        assert split["held_out"] and split["fine_tune"]
    assert split_by_cluster(list(reversed(entries)), 0.5, trial) == split  # deterministic, order-free


def test_split_share_and_seed():
    entries = [{"cluster": f"s{i % 3}/collision/r{i}", "scenario": f"m{i}"} for i in range(20)]
    assert len(cluster_groups(entries)) == 20
    split = split_by_cluster(entries, 0.3, seed=1)
    assert len(split["held_out"]) == 6 and len(split["fine_tune"]) == 14
    # every parent scenario appears on both sides (dealt in turn within each kind)
    assert {c.split("/")[0] for c in split["held_out_clusters"]} == {"s0", "s1", "s2"}
    others = {tuple(split_by_cluster(entries, 0.3, seed=s)["held_out"]) for s in range(2, 8)}
    assert len(others) > 1  # the seed decides which clusters, not a fixed rule
    tied = [{"cluster": "a/collision/r0", "scenario": "m"}, {"cluster": "b/collision/r0", "scenario": "m"}]
    assert split_by_cluster(tied, 0.5, 0)["groups"] == 1
    with pytest.raises(ValueError, match="fraction"):
        split_by_cluster(entries, 1.5)


def test_fine_tune_weights_keep_the_bank_in_the_mix():
    weights = fine_tune_weights(["a", "b", "c", "m1", "m2"], ["m1", "m2"], 0.5)
    assert weights["m1"] == pytest.approx(0.25) and weights["a"] == pytest.approx(0.5 / 3)
    assert sum(weights.values()) == pytest.approx(1.0)
    assert fine_tune_weights(["a", "b"], [], 0.5) == {"a": 1.0, "b": 1.0}


# --------------------------------------------------------------------------- fine-tuning
def _parameters(spec):
    model = load_policy(spec).model
    return np.concatenate([p.detach().numpy().ravel() for p in model.policy.parameters()])


def test_fine_tune_continues_the_checkpoint_and_writes_a_card(tmp_path):
    out = tmp_path / "ft"
    path = fine_tune("dv2s-ppo", bank_dir=None, out=out, steps=200, weights={SOURCES[0]: 3.0, SOURCES[1]: 1.0},
                     n_envs=1, vec_env="dummy", progress_bar=False, log=lambda _: None)
    card = read_card(path)
    shipped = read_card(SHIPPED_CHECKPOINT)
    start = shipped["training"]["steps"]
    assert card["fine_tune"]["source_steps"] == start
    assert card["training"]["steps"] >= start + 200  # the step counter continues (one rollout of 512)
    assert card["training"]["segments"][-1]["start_step"] == start
    assert card["sampler"]["mode"] == "weighted"
    assert card["sampler"]["final_probabilities"] == pytest.approx({SOURCES[0]: 0.75, SOURCES[1]: 0.25})
    assert card["env_config"] == shipped["env_config"]  # the same reward as the source
    assert (out / "README.md").read_text().count("Fine-tuned from dv2s-ppo") == 1
    before, after = _parameters("dv2s-ppo"), _parameters(f"ppo:{path}")
    assert before.shape == after.shape and not np.allclose(before, after)
    stamp = path.stat().st_mtime_ns
    assert fine_tune("dv2s-ppo", bank_dir=None, out=out, steps=200, weights={SOURCES[0]: 3.0, SOURCES[1]: 1.0},
                     n_envs=1, vec_env="dummy", progress_bar=False, log=lambda _: None) == path
    assert path.stat().st_mtime_ns == stamp  # finished: not trained again
    slow = fine_tune("dv2s-ppo", bank_dir=None, out=tmp_path / "lr", steps=10, weights={SOURCES[0]: 1.0}, n_envs=1,
                     vec_env="dummy", progress_bar=False, learning_rate=1e-5, log=lambda _: None)
    model = load_policy(f"ppo:{slow}").model
    assert model.learning_rate == 1e-5 and model.lr_schedule(0.5) == 1e-5
    assert read_card(slow)["fine_tune"]["learning_rate"] == 1e-5
    with pytest.raises(TrainingError, match="stable-baselines3 checkpoint"):
        fine_tune("rule", bank_dir=None, out=tmp_path / "x", steps=10, weights={SOURCES[0]: 1})


# --------------------------------------------------------------------------- paired evaluation
def test_paired_evaluation_runs_identical_episodes_before_and_after(tmp_path):
    episodes = [(name, EVAL_SEED_BASE + i) for name in SOURCES for i in range(2)]
    store = HeldOutStore(tmp_path / "heldout.jsonl")
    before = evaluate_heldout("before", "keep_lane", episodes, store=store, bank_dir=None, progress=False)
    after = evaluate_heldout("after", "keep_lane", episodes, store=store, bank_dir=None, workers=2, progress=False)
    assert [(r["scenario"], r["seed"]) for r in before] == [(r["scenario"], r["seed"]) for r in after] == episodes
    # same policy, same scene and seed: the very same trajectory, so the pairing is real
    assert [r["result"]["trajectory_hash"] for r in before] == [r["result"]["trajectory_hash"] for r in after]
    summary = paired_summary(before, after)
    assert summary["pairs"] == 4 and summary["table"]["before_only"] == summary["table"]["after_only"] == 0
    assert summary["mcnemar_p"] == 1.0
    # a reopened store serves the finished episodes without running them
    again = evaluate_heldout("before", "no.such:policy", episodes, store=HeldOutStore(tmp_path / "heldout.jsonl"),
                             bank_dir=None, progress=False)
    assert again == before


def test_held_out_workers_that_crash_or_hang_give_error_records_not_failures(tmp_path):
    episodes = [(SOURCES[0], EVAL_SEED_BASE), (SOURCES[1], EVAL_SEED_BASE)]
    store = HeldOutStore(tmp_path / "heldout.jsonl")
    crashed = evaluate_heldout("before", "regress_misbehaving_policies:crash", episodes, store=store, bank_dir=None,
                               workers=2, progress=False)
    assert [(r["scenario"], r["seed"]) for r in crashed] == episodes
    assert all("crashed" in r["error"] and "2 attempts" in r["error"] for r in crashed)
    hung = evaluate_heldout("after", "regress_misbehaving_policies:hang", episodes[:1], store=store, bank_dir=None,
                            workers=2, timeout=3, progress=False)
    assert "hung" in hung[0]["error"]
    # errors are left out of the pairs, never counted as failures, and run again on a reopened store
    assert paired_summary(crashed[:1], hung)["errors"] == 1
    assert HeldOutStore(tmp_path / "heldout.jsonl").records == {}


def test_paired_summary_counts_and_drop():
    def records(outcomes):
        return [{"scenario": f"s{i % 2}", "seed": i, "failed": f, "error": None} for i, f in enumerate(outcomes)]

    before = records([True] * 8 + [False] * 2)
    after = records([True, False, False, False, True, False, False, False, True, False])
    summary = paired_summary(before, after)
    assert summary["before"]["k"] == 8 and summary["after"]["k"] == 3
    assert summary["relative_drop"] == pytest.approx(5 / 8)
    assert summary["table"] == {"both_fail": 2, "after_only": 1, "before_only": 6, "neither": 1}
    assert 0.0 < summary["mcnemar_p"] < 0.2
    assert summary["before"]["low"] < 0.8 < summary["before"]["high"]
    after[0]["error"] = "crashed"
    assert paired_summary(before, after)["pairs"] == 9


# --------------------------------------------------------------------------- the loop
TINY = dict(budget=6, fine_tune_steps=100, k_eval=2, regress_episodes=1, workers=1, n_envs=1, progress=False,
            scenarios=SOURCES, fine_tune_method="ppo", log=lambda _: None)  # DAgger: tests/test_loop_dagger.py


class _Kill(BaseException):
    """Stands for the process being killed mid-step."""


@pytest.mark.slow
def test_loop_resumes_without_redoing_steps_and_reports_every_field(tmp_path, monkeypatch):
    import policies.training as training

    out = tmp_path / "loop"
    miner = FakeMiner(SOURCES, failures_per_round=4)
    real_fine_tune = training.fine_tune
    monkeypatch.setattr(training, "fine_tune", lambda *a, **k: (_ for _ in ()).throw(_Kill()))
    with pytest.raises(_Kill):
        run_loop("dv2s-ppo", out=out, miner=miner, **TINY)
    state = json.loads((out / "loop.json").read_text())
    assert set(state["rounds"][0]["steps"]) == {"mine", "split", "before"}
    held = state["rounds"][0]["steps"]["split"]["held_out"]
    assert len(held) == 2 and len(state["rounds"][0]["steps"]["split"]["fine_tune"]) == 2
    lines_before = (out / "round_1" / "heldout.jsonl").read_text().splitlines()
    assert len(lines_before) == 2 * TINY["k_eval"]

    monkeypatch.setattr(training, "fine_tune", real_fine_tune)
    with pytest.raises(LoopError, match="budget"):
        run_loop("dv2s-ppo", out=out, miner=miner, **{**TINY, "budget": 7})
    report = run_loop("dv2s-ppo", out=out, miner=miner, **TINY)
    assert len(miner.calls) == 1  # mining was not run again
    lines = (out / "round_1" / "heldout.jsonl").read_text().splitlines()
    assert lines[:len(lines_before)] == lines_before and len(lines) == 2 * len(lines_before)  # only "after" ran
    record = report.rounds[0]
    steps = record["steps"]
    assert set(steps) == {"mine", "split", "before", "fine_tune", "after", "regress"}
    assert steps["mine"]["failures"] == 4 and len(steps["mine"]["kept"]) == 4
    assert steps["after"]["pairs"] == 2 * TINY["k_eval"]
    for key in ("before", "after"):
        assert {"k", "n", "rate", "low", "high"} <= set(steps["after"][key])
    assert "relative_drop" in steps["after"] and "mcnemar_p" in steps["after"]
    assert steps["regress"]["verdict"] in ("PASS", "FAIL", "INCONCLUSIVE")
    assert steps["fine_tune"]["mined_upweighted"] == 2  # the held-out ones are not trained on
    card = read_card(steps["fine_tune"]["model"])
    assert not set(held) & set(card["sampler"]["weights"])
    assert set(record["timings"]) >= {"mine", "before", "fine_tune", "after", "regress"}
    assert report.policy == record["new_policy"] and report.policy.startswith("ppo:")
    data = json.loads(report.paths["json"].read_text())
    assert data["schema"] == "dv2s-loop" and data["rounds"][0]["steps"]["regress"]["verdict"]
    markdown = report.paths["md"].read_text()
    assert "held-out failure rate before" in markdown and steps["regress"]["verdict"] in markdown
    page = report.paths["html"].read_text()
    assert page.startswith("<!DOCTYPE html>") and steps["regress"]["verdict"] in page and "http" not in page
    # a finished loop rerun does nothing new
    again = run_loop("dv2s-ppo", out=out, miner=miner, **TINY)
    assert len(miner.calls) == 1 and again.rounds == report.rounds


def test_loop_refuses_a_policy_it_cannot_fine_tune(tmp_path):
    with pytest.raises(LoopError, match="stable-baselines3 checkpoint"):
        run_loop("rule", out=tmp_path / "loop", miner=FakeMiner(SOURCES), **TINY)


@pytest.mark.parametrize("argv, needle", [
    (["--policy", "rule"], "stable-baselines3 checkpoint"),
    (["--budget", "0"], "--budget must be an integer >= 1"),
    (["--holdout-fraction", "2"], "--holdout-fraction must be in [0, 1]"),
    (["--sampler", "no-such"], "--sampler must be one of random, halton"),  # it used to start round 1 first
])
def test_cli_refuses_bad_input_in_one_line(tmp_path, capsys, argv, needle):
    code, _, err = run(capsys, "loop", "--out", tmp_path / "loop", "--no-progress", *argv)
    assert code == 2 and needle in one_line_error(err)
    assert not (tmp_path / "loop").exists()  # refused before anything is written
