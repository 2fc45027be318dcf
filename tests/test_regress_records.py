"""What ``dv2s regress`` writes per episode is a typed record (scenario_bank.records.RegressEpisode): lines of
real runs read and written back change no byte, a bad field is named, and the store, the runner and the report
hand records over."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.failures import apply_failure
from regress_report_data import report_from_json
from dv2s_gym.regress.store import RunStore
from scenario_bank.records import RecordError, RegressEpisode

RESULTS = Path(__file__).resolve().parent / "data" / "regress" / "results.jsonl"
SETTINGS = {"episodes": 1, "seed": 0, "scenarios": ["a"]}


def _lines():
    return [line for line in RESULTS.read_bytes().split(b"\n") if line]


@pytest.mark.parametrize("line", _lines(), ids=lambda line: json.loads(line)["id"] + ":" + json.loads(line)["role"])
def test_a_line_of_a_real_run_reads_and_writes_back_byte_for_byte(line):
    data = json.loads(line)
    record = RegressEpisode.from_dict(data)
    assert json.dumps(record.to_dict(), sort_keys=True, default=str).encode("utf-8") == line
    assert record.to_dict() == data and record == RegressEpisode.from_dict(data) and record != data  # no mapping
    assert record.key == (data["id"], data["role"])
    assert record.result_extra == data.get("extra") and record.extra == {}  # the result's own "extra" is a field
    if data.get("error"):
        assert set(record.to_dict()) == {"id", "role", "scenario", "seed", "error", "trace"} and record.failed is None
    else:
        assert record.failure_kinds == tuple(data["failure_kinds"]) and record.failed == bool(record.failure_kinds)


def test_the_store_reads_a_real_results_file_as_records_and_writes_it_back_unchanged(tmp_path):
    shutil.copy(RESULTS, tmp_path / "results.jsonl")
    (tmp_path / "run.json").write_text(json.dumps({"schema": "dv2s-regress-run", "version": 4, "settings": SETTINGS}))
    with (tmp_path / "results.jsonl").open("a") as handle:
        handle.write('{"id": "cut short')  # a run killed mid-line
    done = RunStore(tmp_path, SETTINGS).open()
    assert all(type(record) is RegressEpisode for record in done.values()) and len(done) == len(_lines())
    again = tmp_path / "again"
    again.mkdir()
    shutil.copy(tmp_path / "run.json", again / "run.json")
    with RunStore(again, SETTINGS, fsync=False) as store:
        store.open()
        for record in done.values():
            store.append(record)
    assert (again / "results.jsonl").read_bytes() == RESULTS.read_bytes()


def test_a_field_of_the_wrong_kind_is_named_and_the_store_refuses_its_line(tmp_path):
    data = json.loads(_lines()[0])
    with pytest.raises(RecordError, match="regression result field 'steps' must be an integer, not str"):
        RegressEpisode.from_dict({**data, "steps": "12"})
    with pytest.raises(RecordError, match="regression result field 'role' is missing"):
        RegressEpisode.from_dict({k: v for k, v in data.items() if k != "role"})
    (tmp_path / "run.json").write_text(json.dumps({"schema": "dv2s-regress-run", "version": 4, "settings": SETTINGS}))
    (tmp_path / "results.jsonl").write_text(json.dumps({**data, "collided": "yes"}) + "\n" + _lines()[1].decode() + "\n")
    with pytest.raises(RegressError, match=r"line 1 is not a result record \(regression result field 'collided' must "
                                           r"be true or false, not str 'yes'\); the file is damaged"):
        RunStore(tmp_path, SETTINGS).open()


def test_a_report_built_from_records_holds_the_same_json_as_one_built_from_their_dicts():
    lines = [json.loads(line) for line in _lines()]
    candidate, baseline = lines[0], lines[1]  # one episode of a real run, both roles
    assert candidate["id"] == baseline["id"]
    bank = {"path": "bank", "version": "v", "scenarios": [candidate["scenario"]], "hashes": {candidate["scenario"]: "h"}}
    settings = {"episodes": 1, "seed": 0, "margin": 0.05, "alpha": 0.05, "failure": ["collision", "off_road"]}

    def report(make):
        episode = {"id": candidate["id"], "scenario": candidate["scenario"], "seed": candidate["seed"],
                   "candidate": make(candidate), "baseline": make(baseline)}
        built = report_from_json(bank=bank, settings=settings, candidate={"spec": "a"}, baseline={"spec": "b"},
                                 episodes=[episode])
        return json.dumps({k: v for k, v in built.to_dict().items() if k != "created"}, sort_keys=True)

    assert report(RegressEpisode.from_dict) == report(dict)
    assert json.loads(report(RegressEpisode.from_dict))["newly_failing"] == [candidate["id"]]


def test_the_failure_kinds_apply_to_a_record_read_as_a_dict():
    record = RegressEpisode.from_dict(json.loads(_lines()[4]))  # the stall
    changed = apply_failure(record.to_dict(), ["collision"])
    assert changed["failed"] is False and changed["failure_kinds"] == []
    assert RegressEpisode.from_dict(changed).failed is False and record.failed is True  # the record is frozen
