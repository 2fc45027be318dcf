"""The typed records of scenario_bank.records: their JSON form is exactly the files' (round trips change no
byte), their checks name the bad field, and the bank and the miner hand them over."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from scenario_bank.entries import new_provenance, new_sidecar, scan_entries
from scenario_bank.errors import BankError, WrongTypeError
from scenario_bank.records import (MINED_PROVENANCE_FIELDS, PROVENANCE_FIELDS, EpisodeRecord, Provenance,
                                   RecordError, Sidecar)

SHIPPED = Path(__file__).resolve().parents[1] / "scenario_bank" / "scenarios"

MINED_SOURCE = {
    "kind": "mined", "video": "failure.webm", "parent": "highway_lead_vehicle_brakes", "seed": 7,
    "generator": "dra=bev,sg=rules", "model": None, "context_hash": "c0ffee", "date": "2026-01-02",
    "params": {"gap": 31.5}, "backends": {"dra": "bev", "sg": "rules"}, "policy": "rule",
    "failure": {"type": "collision", "kind": "collision:rear_end"}, "cluster": "highway/collision:rear_end/x",
    "reproduction": {"k": 4, "reproduced": 3, "rate": 0.75}, "e2e_sc": 0.8, "run": "/runs/a", "trace": "trace.json.gz",
    "index": 12, "interaction": {"actor": "lead"}, "judge": None, "replay": None, "replay_entry": "replay_x",
    "converted": None, "files": ["failure.webm", "trace.json.gz"],
    "merged": [{"kind": "mined", "seed": 9, "how": "near-duplicate"}], "converted_e2e_sc": 0.5,
}

EPISODE = {
    "index": 3, "policy": "random", "scenario": "highway_lead_vehicle_brakes", "seed": 1234,
    "params": {"gap": 20.0}, "result": {"mean_speed": 21.5, "min_ttc": 0.4, "trajectory_hash": "ab"},
    "failure": {"type": "collision", "kind": "collision:rear_end"}, "rho": -1.0,
    "reference": {"policy": "rule", "failure": None}, "avoidable": True, "trace": "traces/000003.json.gz",
    "error": None, "family": "highway_lead_vehicle_brakes", "behaviour": {"actor": "lead"}, "failure_state": [0.5, 1.0],
    "sampler": "random", "point": [0.1, [0.2]], "proposal": None,
}


def _sidecar_bytes(meta) -> bytes:
    return (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode("utf-8")


@pytest.mark.parametrize("folder", sorted(p.parent for p in SHIPPED.glob("*/meta.json")), ids=lambda p: p.name)
def test_every_shipped_sidecar_reads_and_writes_back_byte_for_byte(folder):
    data = (folder / "meta.json").read_bytes()
    sidecar = Sidecar.from_dict(json.loads(data))
    assert _sidecar_bytes(sidecar.to_dict()) == data
    assert sidecar.provenance.kind in ("hand-written", "generated", "mined")
    assert sidecar.map and sidecar.description
    kept = Sidecar.from_checked(sidecar.to_dict())
    assert _sidecar_bytes(kept.to_dict()) == data and isinstance(kept.source, Provenance)
    assert kept.source.to_dict() == sidecar.source.to_dict() and kept.tags == sidecar.tags


def test_a_mined_provenance_round_trips_with_its_unknown_and_null_fields():
    provenance = Provenance.from_dict(MINED_SOURCE)
    assert provenance.to_dict() == MINED_SOURCE
    assert json.dumps(provenance.to_dict(), sort_keys=True) == json.dumps(MINED_SOURCE, sort_keys=True)
    assert provenance.mined and provenance.failure_type == "collision" and not provenance.is_replay
    assert provenance.files == ("failure.webm", "trace.json.gz") and provenance.merged[0]["seed"] == 9
    assert provenance.extra == {"converted_e2e_sc": 0.5}
    assert provenance.to_dict()["parent"] == provenance.parent == "highway_lead_vehicle_brakes"
    assert provenance.to_dict() == MINED_SOURCE


def test_a_field_left_out_stays_out_and_a_null_one_stays_null():
    old = {"kind": "hand-written", "date": "2025-01-01"}  # an older sidecar's source: no other field
    assert Provenance.from_dict(old).to_dict() == old
    assert Provenance.from_dict({"kind": "generated", "video": None}).to_dict() == {"kind": "generated", "video": None}


def test_a_new_provenance_writes_what_a_new_sidecar_always_wrote():
    hand = Provenance(kind="hand-written", video="v.webm").to_dict()
    assert set(hand) == set(PROVENANCE_FIELDS) and hand["video"] == "v.webm" and hand["seed"] is None
    mined = Provenance(kind="mined", parent="p").to_dict()
    assert set(mined) == set(PROVENANCE_FIELDS) | set(MINED_PROVENANCE_FIELDS) - {"merged"}
    assert Provenance(kind="mined", files=("a.webm",)).to_dict()["files"] == ["a.webm"]


def test_to_dict_gives_a_new_dict_each_time():
    provenance = Provenance.from_dict(MINED_SOURCE)
    out = provenance.to_dict()
    out["files"].append("other")
    out["seed"] = 0
    assert provenance.to_dict() == MINED_SOURCE


@pytest.mark.parametrize("field, value, wanted", [
    ("kind", "stolen", "one of"),
    ("seed", "7", "an integer"),
    ("seed", True, "an integer"),
    ("index", 1.5, "an integer"),
    ("parent", 3, "a string"),
    ("failure", "collision", "a JSON object"),
    ("files", ["ok", 3], "a list of strings"),
    ("merged", [{"seed": 1}, "x"], "a list of JSON objects"),
])
def test_a_provenance_field_of_the_wrong_kind_is_named(field, value, wanted):
    with pytest.raises(RecordError, match=f"provenance.*'{field}'.*{wanted}"):
        Provenance.from_dict({**MINED_SOURCE, field: value})


def test_a_record_must_be_an_object():
    with pytest.raises(RecordError, match="must be a JSON object, not list"):
        Provenance.from_dict(["kind", "mined"])


def test_a_sidecar_names_a_missing_or_wrong_field_and_one_of_its_provenance():
    meta = json.loads((SHIPPED / "highway_lead_vehicle_brakes" / "meta.json").read_text())
    with pytest.raises(RecordError, match="sidecar field 'map' is missing"):
        Sidecar.from_dict({k: v for k, v in meta.items() if k != "map"})
    with pytest.raises(RecordError, match="sidecar field 'tags' must be a list of strings"):
        Sidecar.from_dict({**meta, "tags": "highway"})
    with pytest.raises(RecordError, match="sidecar field 'source.seed' must be an integer"):
        Sidecar.from_dict({**meta, "source": {"kind": "mined", "seed": "x"}})


def test_new_sidecar_takes_a_provenance_record_or_its_mapping_alike():
    script = "param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n"
    given = {"kind": "mined", "parent": "p", "seed": 3, "params": {"a": 1}, "date": "2026-01-02"}
    from_mapping = new_sidecar(script, "A car.", "a_car", None, ["b", "a"], None, given, None)
    from_record = new_sidecar(script, "A car.", "a_car", None, ["b", "a"], None, Provenance(**given), None)
    assert isinstance(from_record, Sidecar)
    assert _sidecar_bytes(from_mapping.to_dict()) == _sidecar_bytes(from_record.to_dict())
    meta = from_record.to_dict()
    assert meta["tags"] == ["a", "b"] and meta["map"] == "highway_straight"
    assert meta["source"]["replay"] is None and "merged" not in meta["source"]
    assert Sidecar.from_dict(meta).to_dict() == meta


def test_a_new_provenance_defaults_its_kind_and_date_and_refuses_a_bad_field():
    made = new_provenance({"video": "v.webm", "kind": ""})
    assert made.kind == "hand-written" and made.date and made.video == "v.webm"
    with pytest.raises(BankError, match="provenance kind"):
        new_provenance({"kind": "stolen"})
    with pytest.raises(BankError, match="'seed' must be an integer"):
        new_provenance({"seed": "3"})


def test_a_listed_entry_carries_its_typed_sidecar_and_a_malformed_one_is_a_problem_naming_its_file(tmp_path):
    for name, source in [("mined_x", MINED_SOURCE), ("broken", {"kind": "mined", "parent": 5})]:
        (tmp_path / name).mkdir()
        (tmp_path / name / "scenario.scenic").write_text("ego = new Car\n")
        (tmp_path / name / "meta.json").write_text(json.dumps({"description": "d", "map": "m", "source": source}))
    listing = scan_entries(tmp_path, {})
    entry = listing.entries["mined_x"]
    assert isinstance(entry.sidecar, Sidecar) and isinstance(entry.source, Provenance)
    assert entry.source.parent == "highway_lead_vehicle_brakes" and entry.source.to_dict() == MINED_SOURCE
    assert entry.sidecar.source is entry.source and entry.sidecar.description == "d"
    assert listing.index["mined_x"]["meta"] == entry.sidecar.to_dict()
    assert list(listing.entries) == ["mined_x"]
    assert listing.problems["broken"] == ("bad sidecar broken/meta.json: sidecar field 'source.parent' must be a "
                                          "string, not int 5")
    cached = scan_entries(tmp_path, listing.index).entries["mined_x"]
    assert cached.source == entry.source and cached.sidecar.to_dict() == entry.sidecar.to_dict()


def test_an_episode_record_round_trips_and_reads_its_outcome():
    record = EpisodeRecord.from_dict(EPISODE)
    assert record.to_dict() == EPISODE and record == EpisodeRecord.from_dict(EPISODE) and record != EPISODE
    assert record.failure_state == (0.5, 1.0) and "worker_restarts" not in record.to_dict()
    assert record.id == "highway_lead_vehicle_brakes/1234" and record.failed and record.outcome == "failed"
    assert record.failure_type == "collision" and record.mean_speed == 21.5 and record.min_ttc == 0.4
    assert record.to_dict()["point"] == [0.1, [0.2]] and "missing" not in record.to_dict()
    errored = EpisodeRecord.from_dict({**EPISODE, "error": "RuntimeError: x", "result": None})
    assert errored.outcome == "error" and not errored.failed and errored.failure_type is None
    assert math.isinf(errored.min_ttc) and errored.mean_speed is None
    passed = EpisodeRecord(index=0, scenario="s", seed=1, sampler="random", point=[0.5])
    assert passed.outcome == "passed" and not passed.failed
    written = passed.to_dict()
    assert written["failure"] is None and written["error"] is None and "behaviour" not in written


@pytest.mark.parametrize("change, wanted", [
    ({"seed": None}, "'seed' is missing"),
    ({"index": "3"}, "'index' must be an integer"),
    ({"rho": "low"}, "'rho' must be a number"),
    ({"avoidable": 1}, "'avoidable' must be true or false"),
    ({"worker_restarts": "twice"}, "'worker_restarts' must be a list"),
    ({"failure_state": {"speed": 1.0}}, "'failure_state' must be a list"),
])
def test_an_episode_record_field_of_the_wrong_kind_is_named(change, wanted):
    with pytest.raises(RecordError, match=f"episode record field {wanted}"):
        EpisodeRecord.from_dict({**EPISODE, **change})


def test_the_miner_writes_and_reads_its_records_as_episode_records(tmp_path):
    from dv2s_gym.mining.errors import MiningError
    from dv2s_gym.mining.jsonl import JsonlAppender
    from dv2s_gym.mining.miner import read_records

    path = tmp_path / "episodes.jsonl"
    appender = JsonlAppender(path)
    appender.append(EpisodeRecord.from_dict(EPISODE))
    appender.append(EpisodeRecord.from_dict({**EPISODE, "index": 4, "behaviour": None}))
    with pytest.raises(WrongTypeError, match="episodes.jsonl holds typed records, not dict: read a JSON object"):
        appender.append({**EPISODE, "index": 5})
    appender.close()
    lines = path.read_bytes().splitlines()
    assert lines[0] == json.dumps(EPISODE, sort_keys=True).encode("utf-8")
    records = read_records(path)
    assert [type(r) for r in records] == [EpisodeRecord, EpisodeRecord]
    assert [r.index for r in records] == [3, 4] and records[1].to_dict()["behaviour"] is None
    path.write_text(json.dumps({**EPISODE, "seed": "x"}) + "\n" + json.dumps({**EPISODE, "index": 4}) + "\n")
    with pytest.raises(MiningError, match="episode 3: episode record field 'seed' must be an integer"):
        read_records(path)
