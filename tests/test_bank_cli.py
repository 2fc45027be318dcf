"""`dv2s bank` subcommands on a temporary bank: human and --json output, exit codes."""

import json
import shutil
import textwrap

import pytest

from cli_helpers import run

SCRIPT = textwrap.dedent(
    """\
    # 1. Map and global parameters
    param map = 'highway_straight'
    model scenic.domains.driving.model
    param gap = Range({lo}, 30)
    # 2. Adversarial behaviours
    # 3. Road geometry
    lane = Uniform(*network.lanes)
    # 4. Spawn positions
    ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
    lead = new Car following roadDirection from ego for globalParameters.gap,
        with behavior FollowLaneBehavior(target_speed=15)
    """
)


@pytest.fixture
def bank(tmp_path):
    return str(tmp_path / "bank")


# about 2 s of CPU, kept in the quick run: the bank command's one end-to-end check there
def test_add_list_show_sample_stats_rm(bank, tmp_path, capsys):
    script = tmp_path / "lead.scenic"
    script.write_text(SCRIPT.format(lo=10))
    elements = tmp_path / "elements.json"
    elements.write_text(json.dumps({"road": "highway", "participants": ["ego", "car"],
                                    "actions": [["car", "keep_lane"]], "relations": [["car", "ahead_of", "ego"]]}))
    code, out, _ = run(capsys, "bank", "--bank", bank, "add", str(script), "--description", "A car ahead.",
                       "--name", "lead", "--elements", str(elements), "--tag", "highway", "--json")
    assert code == 0 and json.loads(out)["name"] == "lead"
    code, out, err = run(capsys, "bank", "--bank", bank, "add", str(script), "--description", "again", "--name", "x")
    assert code == 2 and "identical" in err and "'lead'" in err
    code, out, _ = run(capsys, "bank", "--bank", bank, "list", "--element", "ahead_of", "--json")
    assert [s["name"] for s in json.loads(out)["scenarios"]] == ["lead"]
    code, out, _ = run(capsys, "bank", "--bank", bank, "show", "lead")
    assert code == 0 and "A car ahead." in out and "param gap" in out
    code, out, _ = run(capsys, "bank", "--bank", bank, "sample", "--count", "3", "--json")
    assert json.loads(out) == ["lead"] * 3
    code, out, _ = run(capsys, "bank", "--bank", bank, "stats", "--json")
    assert json.loads(out)["scenarios"] == 1
    code, out, _ = run(capsys, "bank", "--bank", bank, "rm", "lead")
    assert code == 0
    code, out, _ = run(capsys, "bank", "--bank", bank, "list", "--json")
    assert json.loads(out)["scenarios"] == []


@pytest.mark.slow
def test_export_import_and_validate_exit_codes(bank, tmp_path, capsys):
    script = tmp_path / "lead.scenic"
    script.write_text(SCRIPT.format(lo=12))
    assert run(capsys, "bank", "--bank", bank, "add", str(script), "--description", "A car ahead.", "--name", "good")[0] == 0
    broken = tmp_path / "broken.scenic"
    broken.write_text(SCRIPT.format(lo=14).replace("FollowLaneBehavior", "FollowLaneBehaviour"))
    code, _, err = run(capsys, "bank", "--bank", bank, "add", str(broken), "--description", "Broken.", "--name", "broken")
    assert code == 2 and "sandboxed check" in err and "FollowLaneBehaviour" in err  # add runs what it accepts
    archive = tmp_path / "a.tar.gz"
    assert run(capsys, "bank", "--bank", bank, "export", str(archive))[0] == 0
    other = str(tmp_path / "other")
    code, out, _ = run(capsys, "bank", "--bank", other, "import", str(archive), "--json")
    assert code == 0 and sorted(json.loads(out)["added"]) == ["good"]
    # a broken entry left by hand (or by an older dv2s-gym) is what validate reports
    from pathlib import Path

    from scenario_bank.bank import content_hash

    planted = Path(bank) / "broken"
    shutil.copytree(Path(bank) / "good", planted)
    (planted / "scenario.scenic").write_text(broken.read_text())
    meta = json.loads((planted / "meta.json").read_text())
    meta.update(name="broken", content_hash=content_hash(broken.read_text()), description="Broken.")
    (planted / "meta.json").write_text(json.dumps(meta))
    assert run(capsys, "bank", "--bank", bank, "export", str(archive))[0] == 0
    code, _, err = run(capsys, "bank", "--bank", str(tmp_path / "third"), "import", str(archive))
    assert code == 2 and "archive entry 'broken'" in err and "nothing was imported" in err
    code, out, _ = run(capsys, "bank", "--bank", bank, "validate", "--samples", "1", "--seconds", "1", "--json")
    reports = {r["name"]: r for r in json.loads(out)}
    assert code == 1
    assert reports["good"]["ok"] and reports["good"]["compile_seconds"] is not None
    assert reports["good"]["acceptance_rate"] > 0 and reports["good"]["episodes"][0]["steps"] > 0
    assert not reports["broken"]["ok"] and "FollowLaneBehaviour" in reports["broken"]["error"]
    assert run(capsys, "bank", "--bank", bank, "validate", "good", "--samples", "1", "--seconds", "1")[0] == 0


def test_bank_list_has_a_header_and_columns_as_wide_as_the_longest_name(capsys):
    code, out, _ = run(capsys, "bank", "list")
    lines = out.splitlines()
    assert code == 0 and lines[0].split() == ["name", "map", "source", "tags"]
    rows = lines[1:-1]
    longest = max(len(line.split()[0]) for line in rows)
    assert longest > 40  # names longer than the old fixed column
    starts = {line.index(line.split()[1], len(line.split()[0])) for line in [lines[0], *rows]}
    assert len(starts) == 1  # the map column starts at one place on every line, the header's included
    assert lines[-1].endswith("scenario(s)")
