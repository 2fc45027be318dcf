"""Exact replays without a conversion: one failing scene kept as a bank entry, and one per cluster of a mining run.

Failure records come from the miner's worker (``keep_lane``, which runs into what stands in its lane), as in
``test_mining_convert.py``.
"""

from __future__ import annotations

import json

import pytest

from dv2s_gym.mining.conversion.record import ConversionStatus, ReplayRow
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.replay import replay_failure_entry
from dv2s_gym.mining.conversion.exact_replay import replay_failure
from scenario_bank.bank import Bank, Sidecar
from scenario_bank.records import EpisodeRecord
from test_mining_convert import SCENARIO, make_record, midpoint

KEEP_LANE = ConversionSettings(policy="keep_lane", monitor={})
"""The conversion settings of the tests: the deterministic policy that fails, the monitors' defaults."""


@pytest.fixture(scope="module")
def record() -> dict:
    return make_record(SCENARIO, 0, midpoint(SCENARIO))


def test_a_failure_is_kept_as_its_exact_replay_without_a_video_or_a_script(record, tmp_path):
    out = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.status == "kept" and out.reason is None and out.scenario == SCENARIO, out
    bank = Bank(tmp_path / "bank")
    entry = bank.get(out.replay_entry)
    assert {"mined", "replay", "collision"} <= set(entry.tags) and entry.source.parent == SCENARIO
    assert entry.source.video is None and entry.source.trace == "trace.json.gz"
    assert not entry.missing_files() and (entry.folder / "trace.json.gz").is_file()
    assert entry.source.interaction["failure_type"] == "collision" and entry.source.e2e_sc == 1.0
    assert replay_failure(bank, out.replay_entry).get("matches") is True  # the recorded episode, step for step
    again = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", KEEP_LANE, bank=bank)
    assert again.replay_entry == out.replay_entry and len(bank) == len(Bank(tmp_path / "bank"))


def test_a_scene_the_reference_driver_failed_too_gets_no_replay_entry(record, tmp_path):
    """The conversion and the loop's replays share the rule: an exact replay is kept only of a scene the reference
    driver passed (it stalled here), and the note says why there is none."""
    failed = dict(record, cluster="c1", reference={"policy": "rule", "failure": {"type": "stall", "kind": "stall"}})
    out = replay_failure_entry(failed, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.status == "kept" and out.replay_entry is None, out
    assert "the reference driver failed this scene too (stall)" in out.note
    assert len(Bank(tmp_path / "bank")) == 0
    passed = dict(failed, reference={"policy": "rule", "failure": None})
    kept = replay_failure_entry(passed, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert kept.replay_entry is not None and kept.note is None


@pytest.mark.slow
def test_a_replay_entry_records_what_it_depends_on_and_a_mismatch_says_why(record, tmp_path):
    from dv2s_gym.mining.conversion.exact_replay import replay_versions
    from policies.run_identity import dv2s_sources_sha256
    from policies.run_identity import installed_version
    from envs.trace import TRACE_VERSION
    from policies.registry import SHIPPED_CHECKPOINT
    from scenario_bank.atomic import file_sha256

    out = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    bank = Bank(tmp_path / "bank")
    name = out.replay_entry
    replay = bank.get(name).source.replay
    assert replay["policy"] == "keep_lane" and replay["policy_sha256"] is None  # a driver, no checkpoint
    assert replay["dv2s_gym_version"] == installed_version() and replay["trace_version"] == TRACE_VERSION
    assert replay["dv2s_sources_sha256"] == dv2s_sources_sha256()
    shipped = file_sha256(SHIPPED_CHECKPOINT)
    assert replay_versions("dv2s-ppo")["policy_sha256"] == shipped
    assert replay_versions(f"ppo:{SHIPPED_CHECKPOINT}")["policy_sha256"] == shipped
    assert replay_versions(str(SHIPPED_CHECKPOINT.parent))["policy_sha256"] == shipped
    matched = replay_failure(bank, name)
    assert matched["matches"] and matched["reason"] is None

    # another version of dv2s-gym recorded it: the episode differs, and the reason names the version
    bank.update_source(name, {"replay": {**replay, "dv2s_gym_version": "0.0.1", "trajectory_hash": "0" * 64}})
    moved = replay_failure(bank, name)
    assert not moved["matches"] and f"dv2s-gym is version {installed_version()} now, 0.0.1 when recorded" in moved["reason"]
    assert "did not replay the recorded failing episode" in moved["reason"] and "checkpoint differs" not in moved["reason"]
    # recorded with a checkpoint: replayed with another one (the shipped dv2s-ppo), the reason names the checkpoint
    # (the recorded hash is replaced too: on some scenes the shipped policy drives exactly as keep-lane does)
    bank.update_source(name, {"replay": {**replay, "policy": "dv2s-ppo", "policy_sha256": "ab" * 32,
                                         "trajectory_hash": "0" * 64}})
    other = replay_failure(bank, name)
    assert not other["matches"]
    assert f"the policy checkpoint differs from the one that failed (SHA-256 {shipped[:12]} now, abababababab when " \
           "recorded)" in other["reason"] and "dv2s-gym is version" not in other["reason"]
    # everything the same: a real divergence
    bank.update_source(name, {"replay": {**replay, "trajectory_hash": "0" * 64}})
    same = replay_failure(bank, name)
    assert not same["matches"] and "a real divergence" in same["reason"]
    # an entry that records none of them: each is named as changed
    bare = {k: v for k, v in replay.items() if k not in replay_versions("keep_lane")}
    bank.update_source(name, {"replay": {**bare, "trajectory_hash": "0" * 64}})
    assert f"dv2s-gym is version {installed_version()} now, None when recorded" in replay_failure(bank, name)["reason"]


def test_a_replay_that_does_not_match_the_recorded_episode_is_rejected_and_adds_nothing(record, tmp_path):
    tampered = json.loads(json.dumps(record))
    tampered["result"]["trajectory_hash"] = "0" * 64
    out = replay_failure_entry(tampered, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.status == "rejected" and out.replay_entry is None
    assert out.reason.startswith("replay: ") and "does not replay the failing episode" in out.reason
    assert not [e for e in Bank(tmp_path / "bank") if e.source.kind == "mined"]
    missing = replay_failure_entry({**record, "failure": None}, tmp_path / "run", KEEP_LANE,
                                   bank=tmp_path / "bank")
    assert missing.status == "rejected" and missing.reason.startswith("input: ")


@pytest.mark.slow
def test_every_cluster_of_a_mining_run_gets_its_replay_once(tmp_path):
    from dv2s_gym.mining.cluster import group
    from dv2s_gym.mining.miner import read_records
    from mining_helpers import mine
    from dv2s_gym.loop.replays import REPLAYS_FILE, replay_clusters, replay_entries

    run_dir = tmp_path / "run"
    mine("keep_lane", out=run_dir, budget=4, sampler="random", scenarios=[SCENARIO], workers=1, reference=None,
         progress=False, reports=False)  # the shipped bank mined; the replays go to another bank
    clusters = set(group(read_records(run_dir / "episodes.jsonl")))
    assert clusters, "keep_lane fails on this scenario"
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", max_replays=1, progress=False)
    assert len(rows) == 1 and rows[0].status == "kept"
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", progress=False)  # resumed: the rest only
    assert sorted(r.cluster for r in rows) == sorted(clusters) and len(rows) == len(clusters)
    assert len((run_dir / REPLAYS_FILE).read_text().splitlines()) == len(clusters)
    entries = replay_entries(run_dir)
    kept = {r.replay_entry for r in rows if r.replay_entry}
    assert {e.scenario for e in entries} == kept and {e.parent for e in entries} == {SCENARIO}
    bank = Bank(tmp_path / "bank")
    assert all(replay_failure(bank, name).get("matches") for name in kept)


@pytest.mark.slow
def test_a_failure_in_a_scenario_without_free_parameters_says_why_it_has_no_replay_entry(tmp_path):
    import re

    script = Bank().get(SCENARIO).script
    fixed = re.sub(r"Range\((\d+), (\d+)\)", lambda m: str((int(m[1]) + int(m[2])) // 2), script)
    fixed = re.sub(r"Uniform\(('[^']*')[^)]*\)", r"\1", fixed)
    bank = Bank(tmp_path / "bank")
    bank.add(fixed, Sidecar(description="A car stands still in the ego's lane ahead.", name="fixed_stopped_car",
                            elements=Bank().get(SCENARIO).elements))
    record = make_record("fixed_stopped_car", 0, {}, bank_dir=str(bank.root))
    out = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", KEEP_LANE, bank=bank)
    assert out.replay_entry is None and len(Bank(bank.root)) == 1
    assert "'fixed_stopped_car' has no free parameters" in out.note, out


def _failed(index, family, actor, rho=0.0):
    return {"index": index, "scenario": family, "family": family, "seed": 1000 + index, "params": {}, "rho": rho,
            "failure": {"type": "collision", "kind": "collision:rear_end"}, "avoidable": True, "error": None,
            "behaviour": {"actor": actor, "actor_manoeuvre": "braking", "ego_manoeuvre": "keeping_lane"}}


def test_exact_replays_take_the_families_in_turn_largest_cluster_first(tmp_path, monkeypatch):
    """Family ``a`` has the three largest clusters (5, 4 and 3 failures), ``b`` one of 2 and ``c`` one of 1: three
    replays are one cluster of each family, not all three of ``a``; the rest follow family by family, and a resumed
    call goes on in the same order."""
    import dv2s_gym.mining.conversion.convert as convert
    from dv2s_gym.mining.cluster import group
    from dv2s_gym.loop.replays import REPLAYS_FILE, replay_clusters

    sizes = [("a", "car", 5), ("a", "truck", 4), ("a", "bicycle", 3), ("b", "car", 2), ("c", "car", 1)]
    records, index = [], 0
    for family, actor, size in sizes:
        for _ in range(size):
            records.append(_failed(index, family, actor, rho=-index))
            index += 1
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "settings.json").write_text(json.dumps({"policy": "dv2s-ppo", "bank_dir": None}))
    (run_dir / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    replayed = []

    def stand_in(record, run_dir, settings, *, bank, cluster):
        replayed.append(cluster)
        return ReplayRow(cluster=cluster, index=record.index, scenario=record.scenario, status=ConversionStatus.KEPT,
                         replay_entry=f"replay_{len(replayed)}")

    monkeypatch.setattr(convert, "replay_failure_entry", stand_in)
    cluster = {(family, actor): f"{family}/collision:rear_end/{actor}-braking/ego-keeping_lane"
               for family, actor, _ in sizes}
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", max_replays=3, progress=False)
    assert [r.cluster for r in rows] == [cluster["a", "car"], cluster["b", "car"], cluster["c", "car"]]
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", max_replays=4, progress=False)  # resumed
    assert [r.cluster for r in rows][3:] == [cluster["a", "truck"]]
    rows = replay_clusters(run_dir, bank_dir=tmp_path / "bank", progress=False)
    assert [r.cluster for r in rows][4:] == [cluster["a", "bicycle"]]
    assert len((run_dir / REPLAYS_FILE).read_text().splitlines()) == len(replayed) == 5
    from dv2s_gym.loop.replays import replay_order

    # deterministic, and the representative is the failure a conversion would take (lowest robustness)
    typed = [EpisodeRecord.from_dict(r) for r in records]
    order = replay_order(group(typed))
    assert order == replay_order(dict(reversed(list(group(typed).items()))))
    assert [r.index for _, r in order] == [4, 13, 14, 8, 11]


def test_an_exact_replay_is_kept_only_of_a_scene_the_reference_driver_passed(tmp_path):
    """The miner calls a near miss 'avoidable' when the reference driver merely stalled in its scene (a stall is
    less severe); the loop counts the stall as a failure too, so that cluster gets no exact replay, and the mining
    summary counts it apart. A reference near miss where the policy collided still counts as passed."""
    from dv2s_gym.mining.cluster import group
    from dv2s_gym.loop.replays import replay_order

    def failing(index, family, kind, reference):
        record = _failed(index, family, "pedestrian")
        record["failure"] = {"type": kind, "kind": kind}
        record["reference"] = {"policy": "rule", "failure": None if reference is None else {"type": reference}}
        return record

    stalled = failing(0, "a", "low_ttc", "stall")
    assert stalled["avoidable"] is True  # the miner's flag says avoidable: the reference's stall is less severe
    passed = failing(1, "b", "low_ttc", None)
    near = failing(2, "c", "collision", "low_ttc")
    unchecked = dict(_failed(3, "d", "car"), reference=None)
    records = [stalled, passed, near, unchecked]
    order = replay_order(group([EpisodeRecord.from_dict(r) for r in records]))
    assert sorted(r.index for _, r in order) == [1, 2, 3]  # no replay of the scene the reference stalled in
    from dv2s_gym.loop.mined import mining_summary
    from dv2s_gym.loop.replays import reference_passed

    assert not reference_passed(stalled)
    assert reference_passed(passed) and reference_passed(near) and reference_passed(unchecked)
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    assert mining_summary(tmp_path).clusters_reference_failed == 1


def test_a_conversion_takes_a_failure_whose_scene_the_reference_driver_passed(tmp_path, monkeypatch):
    """A cluster's most severe failure is a scene the reference driver stalled in: the conversion takes the next
    one, whose exact replay can be kept; a cluster with no such failure is still converted, from its worst."""
    from types import SimpleNamespace

    from dv2s_gym.mining import miner
    from dv2s_gym.mining.settings import MineSettings

    def failing(index, actor, rho, reference):
        return dict(_failed(index, "a", actor, rho=rho), reference={"policy": "rule", "failure": reference})

    records = [failing(0, "car", -3.0, {"type": "stall"}), failing(1, "car", -1.0, None),
               failing(2, "truck", -2.0, {"type": "stall"}), failing(3, "truck", -1.0, {"type": "collision"})]
    taken = []

    def convert(record, out, settings, *, bank, cluster):
        taken.append(record.index)
        return {"cluster": cluster, "index": record.index, "status": "rejected"}

    monkeypatch.setattr(miner, "convert_failure", convert)
    monkeypatch.setattr(miner, "_reached_bank", lambda *_: None)
    run = SimpleNamespace(out=tmp_path, records=[EpisodeRecord.from_dict(r) for r in records],
                          policy="keep_lane", settings=MineSettings())
    miner.convert_clusters(run, ConversionSettings(), bank_dir=str(tmp_path / "bank"), progress=False)
    assert sorted(taken) == [1, 2]


def test_a_failure_in_a_scenario_with_a_discrete_parameter_is_kept_and_replays(tmp_path):
    """A parameter drawn from a set of numbers (``Uniform(8, 10, 12)``) is fixed in the replay script at its failing
    value; the replay then conditions on the parameters the script still draws, and plays the failing episode."""
    from dv2s_gym.mining.sampling.space import SceneSpace

    script = Bank().get(SCENARIO).script.replace("param ego_speed = Range(8, 13)", "param ego_speed = Uniform(8, 10, 12)")
    assert "Uniform(8, 10, 12)" in script
    bank = Bank(tmp_path / "bank")
    bank.add(script, Sidecar(description="A car stands still in the ego's lane ahead.", name="discrete_stopped_car",
                             elements=Bank().get(SCENARIO).elements))
    params = {name: r.from_unit(0.5) for name, r in
              SceneSpace(["discrete_stopped_car"], bank_dir=str(bank.root)).param_ranges("discrete_stopped_car").items()}
    assert params["ego_speed"] in (8, 10, 12)
    record = make_record("discrete_stopped_car", 0, params, bank_dir=str(bank.root))
    settings = ConversionSettings(policy="keep_lane", monitor={}, bank_dir=str(bank.root))
    out = replay_failure_entry(dict(record, cluster="c1"), tmp_path / "run", settings, bank=bank)
    assert out.status == "kept" and out.replay_entry is not None, out
    entry = Bank(bank.root).get(out.replay_entry)
    assert f"param ego_speed = {params['ego_speed']!r}" in entry.script or \
        f"param ego_speed = {int(params['ego_speed'])}" in entry.script
    assert replay_failure(Bank(bank.root), out.replay_entry).get("matches") is True
