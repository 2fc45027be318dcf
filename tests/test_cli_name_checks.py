"""Misspelt scenario and policy names on the command line: refused with a suggestion before the command's
slow start-up (no Scenic or highway-env import)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cli_helpers import one_line_error, run

ROOT = Path(__file__).resolve().parents[1]
BRAKES = "highway_lead_vehicle_brakes"


@pytest.mark.parametrize("argv, expected", [
    (["run", "no_such_scenario"], "unknown scenario 'no_such_scenario'"),
    (["run", "tag:nosuchtag"], "no scenario carries tag 'nosuchtag'. Tags in the bank:"),
    (["regress", "--policy", "rulee", "--baseline", "rule", "--scenarios", BRAKES, "--episodes", "2"],
     "unknown policy 'rulee' (did you mean 'rule'?)"),
    (["regress", "--policy", "rule", "--baseline", "keeplane", "--episodes", "2"],
     "unknown policy 'keeplane' (did you mean 'keep_lane'?)"),
    (["regress", "--policy", "rule", "--scenarios", "highway_lead_vehicle_brake", "--episodes", "2"],
     "unknown scenario 'highway_lead_vehicle_brake'"),
    (["mine", "--policy", "rule", "--reference", "idmm", "--budget", "2", "--no-convert"],
     "unknown policy 'idmm' (did you mean 'idm'?)"),
    (["mine", "--policy", "rule", "--scenarios", "tag:higway", "--budget", "2", "--no-convert"],
     "no scenario carries tag 'higway'. Did you mean 'highway'?"),
])
def test_a_misspelt_name_is_refused_before_the_slow_imports(argv, expected, tmp_path):
    # a fresh interpreter, so that what was imported before the refusal can be seen
    code = ("import sys\nfrom dv2s_gym.cli import main\nstatus = main(sys.argv[1:])\n"
            "heavy = sorted(m for m in ('scenic', 'highway_env', 'envs.dv2s_env', 'torch') if m in sys.modules)\n"
            "print('imported:', heavy)\nsys.exit(status)\n")
    result = subprocess.run([sys.executable, "-c", code, *argv, "--out", str(tmp_path / "out")] if argv[0] != "run"
                            else [sys.executable, "-c", code, *argv, "--video", str(tmp_path / "v.webm")],
                            capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 2, result.stderr
    assert expected in one_line_error(result.stderr)
    assert "imported: []" in result.stdout
    assert not (tmp_path / "out").exists() and not (tmp_path / "v.webm").exists()


def test_the_tag_suggestion_is_left_out_when_no_tag_is_close(capsys):
    code, _, err = run(capsys, "run", "tag:nosuchtag")
    assert code == 2 and "Did you mean" not in one_line_error(err)
    code, _, err = run(capsys, "run", "tag:higway")
    assert code == 2 and "Did you mean 'highway'?" in one_line_error(err)


def test_valid_specs_pass_the_early_check():
    from policies.registry import check_policy_spec

    for spec in ("rule", "rule?action_noise=0.3", "keep_lane", "dv2s-ppo", "ppo:model.zip", "model.zip",
                 "my_module:driver"):
        check_policy_spec(spec)


def test_the_scenarios_of_a_bank_folder_not_made_yet_are_left_to_the_command(tmp_path):
    from dv2s_gym.cli.name_checks import check_names
    from scenario_bank import UnknownScenarioError

    check_names(scenarios=[BRAKES], bank=str(tmp_path / "new_bank"))  # `dv2s mine --bank NEW` copies the bank
    with pytest.raises(UnknownScenarioError):
        check_names(scenarios=["nosuch"], bank=None)
