"""Near-duplicate merging in the bank (``Bank.add(..., on_duplicate="merge")``) and several miners writing to one
bank at once."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import shutil

import pytest

from scenario_bank.bank import BANK_DIR, WRITERS_LOCK, Bank, near_duplicate, param_ranges
from scenario_bank.elements import Elements
from scenario_bank.records import Provenance, Sidecar
from scenario_bank.sandbox import verify_script

BASE = "highway_lead_vehicle_stopped"
SCRIPT = (BANK_DIR / BASE / "scenario.scenic").read_text(encoding="utf-8")
ELEMENTS = Elements.from_dict(json.loads((BANK_DIR / BASE / "meta.json").read_text(encoding="utf-8"))["elements"])
GAP = "param stopped_gap = Range(60, 120)"
assert GAP in SCRIPT


def variant(low: int, high: int) -> str:
    """The shipped script with another range of the stopped car's gap."""
    return SCRIPT.replace(GAP, f"param stopped_gap = Range({low}, {high})")


A, A_NEAR, B = variant(60, 119), variant(100, 125), variant(150, 200)  # A ~ A_NEAR overlap; B overlaps neither


def mined(index: int) -> dict:
    return {"kind": "mined", "parent": BASE, "seed": index, "index": index, "policy": "keep_lane"}


def test_param_ranges_reads_the_numeric_parameters():
    script = ("param map = 'highway_straight'\nparam weather = Uniform('ClearNoon', 'WetNoon')\n"
              "param a = Range(20, 26)\nparam b = -Range(14, 22)  # behind\nparam c = 3.5\n"
              "param d = Uniform(1, 2, 5)\nparam e = Range(1, x)\nparam f = DiscreteRange(2, 4)\n")
    assert param_ranges(script) == {"a": (20, 26), "b": (-22, -14), "c": (3.5, 3.5), "d": (1, 5), "f": (2, 4)}


def test_near_duplicate_needs_same_map_elements_and_overlapping_ranges():
    assert near_duplicate(ELEMENTS, "highway_straight", A, ELEMENTS, "highway_straight", A_NEAR)
    assert not near_duplicate(ELEMENTS, "highway_straight", A, ELEMENTS, "highway_straight", B)
    assert not near_duplicate(ELEMENTS, "highway_straight", A, ELEMENTS, "highway_two_way", A_NEAR)
    other = dataclasses.replace(ELEMENTS, actions=(("car", "stop"), ("car", "brake")))
    assert not near_duplicate(ELEMENTS, "highway_straight", A, other, "highway_straight", A_NEAR)
    # touching intervals overlap; parameters only one script has do not matter
    assert near_duplicate(ELEMENTS, "m", variant(60, 100), ELEMENTS, "m", variant(100, 130) + "\nparam z = Range(0, 1)\n")


@pytest.mark.slow
def test_add_with_merge_adds_then_merges_into_the_existing_sidecar(tmp_path):
    bank = Bank(tmp_path / "bank")
    first = bank.add(A, Sidecar(description="A stopped car ahead.", name="mined_stop", elements=ELEMENTS,
                                source=mined(1)), on_duplicate="merge")
    assert first.status == "added" and first.entry.name == "mined_stop"
    assert first.entry.source.kind == "mined" and first.entry.source.index == 1
    assert first.entry.source.to_dict()["reproduction"] is None  # every mined field is present, unknown ones None
    near = bank.add(A_NEAR, Sidecar(description="A car stands still ahead.", name="mined_stop", elements=ELEMENTS,
                                    source=mined(2)), on_duplicate="merge")
    assert near.status == "merged" and near.entry.name == "mined_stop" and "near-duplicate" in near.how
    same = bank.add(A, Sidecar(description="The same script again.", elements=ELEMENTS, source=mined(3)),
                    on_duplicate="merge")
    assert same.status == "merged" and "byte-for-byte" in same.how
    far = bank.add(B, Sidecar(description="A stopped car far ahead.", name="mined_stop", elements=ELEMENTS,
                              source=mined(4)), on_duplicate="merge")
    assert far.status == "added" and far.entry.name == "mined_stop_2"

    reread = Bank(tmp_path / "bank")
    assert reread.names() == ["mined_stop", "mined_stop_2"] and not reread.problems
    merged = reread.get("mined_stop").source.merged
    assert [m["index"] for m in merged] == [2, 3]
    assert merged[0]["description"] == "A car stands still ahead." and merged[0]["content_hash"]
    assert reread.get("mined_stop").script == A  # the entry itself is unchanged
    assert "merged" not in reread.get("mined_stop_2").source.to_dict()
    # Bank.add keeps refusing duplicates
    from scenario_bank.bank import DuplicateScenarioError

    with pytest.raises(DuplicateScenarioError):
        bank.add(A, Sidecar(description="again", elements=ELEMENTS))


@pytest.mark.slow
def test_old_sidecars_load_and_take_merges(tmp_path):
    shutil.copytree(BANK_DIR / BASE, tmp_path / "bank" / BASE)  # a sidecar without any mined field
    bank = Bank(tmp_path / "bank")
    assert bank.names() == [BASE] and not bank.problems
    outcome = bank.add(A, Sidecar(description="stopped car", elements=ELEMENTS, map="highway_straight",
                                  source=mined(9)), on_duplicate="merge")
    assert outcome.status == "merged" and outcome.entry.name == BASE
    assert Bank(tmp_path / "bank").get(BASE).source.merged[0]["index"] == 9


def test_a_malformed_merged_list_is_reported_for_its_entry(tmp_path):
    shutil.copytree(BANK_DIR / BASE, tmp_path / "bank" / BASE)
    meta_path = tmp_path / "bank" / BASE / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["source"]["merged"] = "not a list"
    meta_path.write_text(json.dumps(meta))
    bank = Bank(tmp_path / "bank")
    assert bank.names() == [] and "source.merged" in bank.problems[BASE]


def _miner(bank_dir: str, order: list, start, results) -> None:
    """One miner process: waits for the others, then adds its scripts as fast as it can."""
    out = []
    try:
        bank = Bank(bank_dir)
        start.wait(timeout=120)
        for index, label in order:
            script = {"A": A, "A_NEAR": A_NEAR, "B": B}[label]
            outcome = bank.add(script, Sidecar(description=f"scenario {label} from miner {index}", name="mined_stop",
                                               elements=ELEMENTS, source=mined(index)), on_duplicate="merge")
            out.append((index, label, outcome.status, outcome.entry.name))
    except Exception as error:  # reported to the test, which fails on it
        out.append((-1, "error", f"{type(error).__name__}: {error}", None))
    results.put(out)


@pytest.mark.slow
@pytest.mark.parametrize("miners", [2, 4])
def test_several_miners_writing_to_one_bank_keep_it_consistent(tmp_path, miners):
    for script in (A, A_NEAR, B):  # sandbox once here (cached by content); the race is the bank's
        verify_script(script, name="warm-up")
    ctx = multiprocessing.get_context("fork")
    start, results = ctx.Barrier(miners), ctx.Queue()
    labels = ["A", "A_NEAR", "B"]
    processes = []
    for m in range(miners):
        order = [(10 * m + i, labels[(i + m) % 3]) for i in range(3)] * 2  # each script twice, rotated
        order = [(index + 100 * (j // 3), label) for j, (index, label) in enumerate(order)]
        processes.append(ctx.Process(target=_miner, args=(str(tmp_path / "bank"), order, start, results)))
    for p in processes:
        p.start()
    outcomes = [row for _ in processes for row in results.get(timeout=300)]
    for p in processes:
        p.join(timeout=60)
        assert p.exitcode == 0
    assert not [row for row in outcomes if row[1] == "error"]

    bank = Bank(tmp_path / "bank")
    assert not bank.problems and len(bank) == 2  # one entry for A ~ A_NEAR, one for B; none lost, none twice
    assert sum(status == "added" for _, _, status, _ in outcomes) == 2
    by_label = {label: {name for _, lab, _, name in outcomes if lab == label} for label in labels}
    assert by_label["A"] == by_label["A_NEAR"] and len(by_label["A"]) == 1 and by_label["B"] != by_label["A"]
    indices = []
    for entry in bank:
        indices.append(entry.source.index)
        indices += [m["index"] for m in entry.source.merged or ()]
        json.loads((entry.folder / "meta.json").read_text())  # whole, parseable sidecars
    assert sorted(indices) == sorted(index for index, _, _, _ in outcomes)  # every failure recorded exactly once
    leftovers = [p.name for p in (tmp_path / "bank").glob(".*")]
    assert leftovers == [WRITERS_LOCK]  # the writers' lock, and no staging or temporary leftovers


def test_update_source_sets_provenance_fields_atomically_and_refuses_the_structural_ones(tmp_path):
    from scenario_bank.bank import BankError, UnknownScenarioError

    bank = Bank(tmp_path / "bank")
    entry = bank.add(A, Sidecar(description="A stopped car ahead.", name="mined_stop", elements=ELEMENTS,
                                source=mined(1)))
    updated = bank.update_source(entry.name, {"converted": "mined_other", "converted_e2e_sc": 0.5})
    assert updated.source.converted == "mined_other" and updated.source.index == 1
    reread = Bank(tmp_path / "bank").get(entry.name)
    assert reread.source.extra["converted_e2e_sc"] == 0.5 and reread.script == A and reread.content_hash == entry.content_hash
    for field in ("kind", "merged", "files"):
        with pytest.raises(BankError, match="cannot set"):
            bank.update_source(entry.name, {field: []})
    with pytest.raises(UnknownScenarioError):
        bank.update_source("no_such_entry", {"converted": None})
    assert not list((tmp_path / "bank").glob(".staging-*")) and not Bank(tmp_path / "bank").problems


def test_add_names_an_unknown_on_duplicate_and_a_near_copy_rule_without_merging(tmp_path):
    bank = Bank(tmp_path / "bank")
    with pytest.raises(ValueError, match="on_duplicate must be one of 'error', 'merge', not 'skip'"):
        bank.add(A, Sidecar(description="A stopped car ahead.", elements=ELEMENTS), on_duplicate="skip")
    with pytest.raises(ValueError, match="near_copy_of only applies to on_duplicate='merge'"):
        bank.add(A, Sidecar(description="A stopped car ahead.", elements=ELEMENTS), near_copy_of=lambda entry: True)
    assert not (tmp_path / "bank").exists()  # refused before anything was written


@pytest.mark.slow
def test_add_takes_the_entry_as_one_sidecar_or_its_description_alone(tmp_path):
    """The new entry's fields come as one :class:`Sidecar` (``source``: the provenance, a record or a mapping of its
    fields, written alike byte for byte); a string is the description alone, written as a sidecar holding only it."""
    fields = Sidecar(description="A stopped car ahead.", name="stop", elements=ELEMENTS, tags=("b", "a"),
                     use_case="braking", source=Provenance(kind="mined", parent=BASE, seed=3, date="2026-01-02"))
    by_record = Bank(tmp_path / "record").add(A, fields)
    by_mapping = Bank(tmp_path / "mapping").add(A, fields.replace(source={"kind": "mined", "parent": BASE, "seed": 3,
                                                                          "date": "2026-01-02"}))
    assert by_record.name == by_mapping.name == "stop"
    assert (by_record.folder / "meta.json").read_bytes() == (by_mapping.folder / "meta.json").read_bytes()
    assert by_record.map == "highway_straight"  # an empty map in the record is read from the script
    assert by_record.tags == ["a", "b"] and by_record.sidecar.use_case == "braking" and by_record.source.seed == 3
    by_text = Bank(tmp_path / "text").add(A, "A stopped car ahead.")
    by_description = Bank(tmp_path / "description").add(A, Sidecar(description="A stopped car ahead."))
    assert by_text.name == by_description.name == "stopped_ahead"  # made from the description
    assert (by_text.folder / "meta.json").read_bytes() == (by_description.folder / "meta.json").read_bytes()


def test_add_refuses_fields_as_keywords_and_what_a_new_entry_cannot_take(tmp_path):
    bank = Bank(tmp_path / "bank")
    with pytest.raises(TypeError, match="unexpected keyword argument 'name'"):
        bank.add(A, "A stopped car ahead.", name="stop")
    with pytest.raises(TypeError, match="as a Sidecar or its description as a string, not dict"):
        bank.add(A, {"description": "A stopped car ahead.", "name": "stop"})
    with pytest.raises(TypeError, match="a story or other keys would be lost"):
        bank.add(A, Sidecar(description="A stopped car ahead.", story=["brake"]))
    assert not (tmp_path / "bank").exists()  # refused before anything was written
