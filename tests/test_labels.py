"""Label files: both formats read, malformed ones refused with a clear error; `eval sg` scores against them."""

import json
from pathlib import Path

import pytest

from dv2s_gym.pipeline.convert import label_for
from dv2s_gym.pipeline.evaluate import EVALSET_DIR, collect_items, evaluate, format_results
from dv2s_gym.pipeline.labels import LabelError, read_label
from dv2s_gym.pipeline.metrics import semantic_preservation
from dv2s_gym.pipeline.semantics.text import elements_from_text
from scenario_bank.elements import Elements

# The pipeline issue's example label, in the flat format.
FLAT = {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "brake"]],
        "relations": [["car", "ahead_of", "ego"]]}


def _write(folder: Path, name: str, data) -> Path:
    path = folder / name
    path.write_text(data if isinstance(data, str) else json.dumps(data), encoding="utf-8")
    return path


def test_flat_and_nested_labels_read_the_same(tmp_path):
    flat = read_label(_write(tmp_path, "a.label.json", FLAT))
    nested = read_label(_write(tmp_path, "b.label.json", {"use_case": "brakes", "elements": FLAT}))
    assert flat.elements == nested.elements == Elements.from_dict(FLAT)
    assert (flat.format, nested.format) == ("flat", "nested")
    assert nested.use_case == "brakes" and flat.use_case is None
    with_meta = read_label(_write(tmp_path, "c.label.json", {**FLAT, "use_case": "u", "description": "d"}))
    assert (with_meta.elements, with_meta.use_case, with_meta.description) == (flat.elements, "u", "d")


def test_flat_label_in_an_eval_folder_and_beside_a_video(tmp_path):
    """Before: `KeyError: 'elements'`."""
    _write(tmp_path, "clip.label.json", FLAT)
    (tmp_path / "clip.webm").write_bytes(b"")
    (item,) = collect_items(tmp_path)
    assert item.elements == Elements.from_dict(FLAT) and item.video.endswith("clip.webm")
    assert item.use_case == "unlabeled"
    assert label_for(tmp_path / "clip.webm") == Elements.from_dict(FLAT)


@pytest.mark.parametrize("content, message", [
    ("{not json", "is not valid JSON"),
    ("[1, 2]", "holds a JSON list, not an object"),
    ({"use_case": "x"}, "has no elements"),
    ({"elements": FLAT, "road": "highway"}, "has both 'elements' and top-level element fields"),
    ({**FLAT, "actions": [["car", "fly"]]}, "unknown action 'fly'"),
    ({**FLAT, "relations": [["car", "ahead_of"]]}, "each relation must be a list of 3 strings"),
    ({"elements": {**FLAT, "road": "moon"}}, "unknown road type 'moon'"),
    ({"elements": None}, "elements must be a JSON object"),
    ({**FLAT, "actions": 3}, "label file"),
    ({**FLAT, "description": 5}, "'description' must be a string"),
])
def test_malformed_label_is_a_clear_error(tmp_path, content, message):
    path = _write(tmp_path, "bad.label.json", content)
    with pytest.raises(LabelError, match=message) as info:
        read_label(path)
    assert str(path) in str(info.value)
    assert isinstance(info.value, ValueError)  # the CLI reports ValueErrors as one line
    with pytest.raises(LabelError, match=message):
        collect_items(tmp_path)


NONSENSE = {"road": "roundabout", "participants": ["ego", "truck", "truck", "pedestrian"],
            "actions": [["truck", "drift"], ["pedestrian", "cross"], ["ego", "turn_right"]],
            "relations": [["truck", "behind", "ego"]]}


@pytest.fixture(scope="module")
def sg_report(tmp_path_factory):
    """`eval sg` over one description three ways: its real label, a nonsense label, and no label."""
    source = read_label(EVALSET_DIR / "highway_lead_vehicle_brakes_seed0.label.json")
    folder = tmp_path_factory.mktemp("sg_eval")
    _write(folder, "real.label.json", {"use_case": "real", "description": source.description,
                                       "elements": source.elements.to_dict()})
    _write(folder, "nonsense.label.json", {**NONSENSE, "use_case": "nonsense", "description": source.description})
    _write(folder, "free.txt", source.description)
    report = evaluate("sg", folder, progress=False)
    return source, {item["stem"]: item for item in report["items"]}, report


@pytest.mark.slow
def test_eval_sg_scores_against_the_label(sg_report):
    source, items, _ = sg_report
    real = items["real"]
    assert real["ok"] and real["reference"] == "label"
    assert real["metrics"]["SP"] == pytest.approx(semantic_preservation(source.elements, real["detail"]["simulated"]))


@pytest.mark.slow
def test_eval_sg_with_nonsense_labels_drops(sg_report):
    source, items, _ = sg_report
    nonsense, real = items["nonsense"], items["real"]
    assert nonsense["reference"] == "label"
    # same description, so the same script ran; only the labels differ
    assert nonsense["detail"]["simulated"] == real["detail"]["simulated"]
    assert nonsense["metrics"]["SP"] == pytest.approx(
        semantic_preservation(Elements.from_dict(NONSENSE), nonsense["detail"]["simulated"]))
    assert nonsense["metrics"]["SP"] < real["metrics"]["SP"] - 0.3


@pytest.mark.slow
def test_eval_sg_falls_back_to_the_text_without_a_label(sg_report):
    source, items, report = sg_report
    free = items["free"]
    assert free["reference"] == "text" and free["use_case"] == "unlabeled"
    assert free["metrics"]["SP"] == pytest.approx(
        semantic_preservation(elements_from_text(source.description), free["detail"]["simulated"]))
    assert report["summary"]["overall"]["reference"] == {"label": 2, "text": 1}
    table = format_results(report)
    assert "S_de from" in table
    assert "2 item(s) scored against their label file, 1 against the parse of their description" in table
    assert "scored against the parsed description: free" in table


def test_eval_dra_and_e2e_still_need_labels(tmp_path):
    _write(tmp_path, "free.txt", "A car brakes in front of the ego car on the highway.")
    with pytest.raises(FileNotFoundError, match="label.json"):
        evaluate("e2e", tmp_path, progress=False)
