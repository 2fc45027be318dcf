"""dv2s regress: bad input is refused before any episode runs, and resume is keyed on what the policies are."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest

from dv2s_gym.cli import main
from dv2s_gym.regress import ResumeMismatchError
from regress_call import run_regression
from policies.registry import PolicyError, load_policy
from policies.run_identity import resume_fingerprint

SCENARIO = "highway_lead_vehicle_brakes"
QUICK = {"duration": 2}

POLICY_MODULE = '''
import numpy as np
from policies.registry import Policy

CALLS = []

class Keep(Policy):
    name = "keep"
    def act(self, observations, deterministic=True):
        return np.full(len(observations), {action}, dtype=np.int64)

def make(**options):
    CALLS.append(options)
    if options.get("broken"):
        raise ValueError("cannot build")
    return Keep()
'''


def regress(*args: str) -> int:
    return main(["regress", *args])


def test_a_misspelt_policy_option_is_bad_input_before_any_episode(tmp_path, capsys):
    with pytest.raises(PolicyError, match="policy 'rule' has no option 'action_nosie'; its options are"):
        load_policy("rule?action_nosie=0.3")
    code = regress("--policy", "rule", "--baseline", "rule?action_nosie=0.3", "--scenarios", SCENARIO, "--episodes",
                   "1", "--out", str(tmp_path), "--no-progress")
    assert code == 2 and "has no option 'action_nosie'" in capsys.readouterr().err
    assert not (tmp_path / "results.jsonl").exists()


@pytest.mark.slow
def test_a_factory_spec_is_called_and_a_module_in_the_current_folder_is_found(tmp_path, monkeypatch):
    (tmp_path / "my_policies_here.py").write_text(POLICY_MODULE.format(action=1))
    monkeypatch.chdir(tmp_path)
    policy = load_policy("my_policies_here:make")
    assert type(policy).__name__ == "Keep"
    import my_policies_here

    assert my_policies_here.CALLS == [{}]  # the factory was called, without options
    with pytest.raises(ValueError, match="cannot build"):
        load_policy("my_policies_here:make?broken=true")
    with pytest.raises(PolicyError, match="returned an int, not a Policy"):
        (tmp_path / "other_policies_here.py").write_text("def make():\n    return 3\n")
        load_policy("other_policies_here:make")
    # the workers find the module in this folder too
    report = run_regression("my_policies_here:make", "rule", scenarios=[SCENARIO], episodes=1, workers=1,
                            out_dir=tmp_path / "out", env_config=QUICK, stall_seconds=1, progress=False)
    assert report.to_dict()["errors"] == [] and report.to_dict()["episodes"][0]["candidate"]["steps"] > 0


@pytest.mark.slow
def test_resume_is_refused_when_the_policy_module_changed_under_the_same_spec(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    module = tmp_path / "resumed_policy_here.py"
    module.write_text(POLICY_MODULE.format(action=1))
    arguments = dict(scenarios=[SCENARIO], episodes=1, workers=1, out_dir=tmp_path / "out", env_config=QUICK, stall_seconds=1,
                     progress=False)
    first = run_regression("resumed_policy_here:make", "rule", **arguments)
    again = run_regression("resumed_policy_here:make", "rule", **arguments)  # unchanged: resumes, runs nothing
    assert again.to_dict()["episodes"] == first.to_dict()["episodes"]
    lines = (tmp_path / "out" / "results.jsonl").read_text().splitlines()
    assert len(lines) == 2
    module.write_text(POLICY_MODULE.format(action=4))  # same spec, other code
    with pytest.raises(ResumeMismatchError, match=r"holds a regression run of resumed_policy_here:make whose policy "
                                                  r"has changed since \(module resumed_policy_here source \(SHA-256\): "
                                                  r"run has [0-9a-f]{12}, now [0-9a-f]{12}\)") as info:
        run_regression("resumed_policy_here:make", "rule", **arguments)
    # the folder's reports are the earlier run's: the refusal says so, and leaves them untouched
    assert "its reports (junit.xml, report.html, report.md, report.json) are that run's, not this one's" in str(info.value)


def test_resume_is_refused_when_the_checkpoint_changed_under_the_same_path(tmp_path):
    checkpoint = tmp_path / "model.zip"
    checkpoint.write_bytes(b"one")
    before = resume_fingerprint(f"ppo:{checkpoint}?device=cpu")
    checkpoint.write_bytes(b"two")
    after = resume_fingerprint(f"ppo:{checkpoint}?device=cpu")
    key = f"checkpoint {checkpoint} (SHA-256)"
    assert before[key] != after[key] and before["options"] == after["options"] == '{"device": "cpu"}'
    assert resume_fingerprint(str(checkpoint))[key] == after[key]
    assert resume_fingerprint("rule?action_noise=0.2")["options"] == '{"action_noise": 0.2}'
    assert any(k.startswith("module policies.rule_based source") for k in resume_fingerprint("rule"))


@pytest.mark.slow
def test_a_baseline_report_from_another_version_is_flagged(tmp_path, capsys):
    old = run_regression("rule", scenarios=[SCENARIO], episodes=1, workers=1, out_dir=tmp_path / "old",
                         env_config=QUICK, stall_seconds=1, progress=False)
    path = tmp_path / "old" / "report.json"
    data = json.loads(path.read_text())
    data["dv2s_version"] = "0.0.1"
    path.write_text(json.dumps(data))
    code = regress("--policy", "rule", "--baseline-report", str(path), "--workers", "1", "--out",
                   str(tmp_path / "new"), "--stall-seconds", "1", "--no-progress")
    printed = capsys.readouterr().out
    assert code in (0, 3)
    warning = f"baseline report {path} was made by dv2s-gym 0.0.1, this is {old.to_dict()['dv2s_version']}"
    assert f"warning: {warning}" in printed
    for name in ("report.md", "report.json", "junit.xml", "report.html"):  # every report carries it
        assert warning in (tmp_path / "new" / name).read_text().replace("&quot;", '"'), name
    suite = ET.parse(tmp_path / "new" / "junit.xml").getroot().find("testsuite")
    assert any(p.get("name") == "warning" and warning in p.get("value") for p in suite.iter("property"))
    assert warning in suite.find("system-err").text


@pytest.mark.slow
def test_resume_key_covers_helper_modules_data_files_and_dv2s_itself(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "stealth_cfg.py").write_text("ACTION = 1\n")
    (tmp_path / "helped_policy_here.py").write_text("import stealth_cfg\n" + POLICY_MODULE.format(action=1))
    (tmp_path / "weights.json").write_text('{"w": 1}')
    spec = "helped_policy_here:make?weights=weights.json"
    before = resume_fingerprint(spec)
    assert before["dv2s version"]
    (tmp_path / "stealth_cfg.py").write_text("ACTION = 4\n")  # the helper the module imports changed
    (tmp_path / "weights.json").write_text('{"w": 2}')  # the data file an option names changed
    after = resume_fingerprint(spec)
    changed = sorted(key for key in before.keys() | after.keys() if before.get(key) != after.get(key))
    assert changed == ["module file stealth_cfg.py beside helped_policy_here (SHA-256)",  # beside the policy module
                       "option weights file weights.json (SHA-256)"]
    from policies import run_identity

    monkeypatch.setattr(run_identity, "dv2s_sources_sha256", lambda: "edited simulator")
    assert run_identity.code_identity()["dv2s sources (SHA-256)"] == "edited simulator"


@pytest.mark.slow
def test_resume_is_refused_when_a_helper_module_of_the_policy_changed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "stealth_cfg2.py").write_text("ACTION = 1\n")
    (tmp_path / "helped_policy_there.py").write_text("import stealth_cfg2\n" + POLICY_MODULE.format(action=1))
    arguments = dict(scenarios=[SCENARIO], episodes=1, workers=1, out_dir=tmp_path / "out", env_config=QUICK, stall_seconds=1,
                     progress=False)
    run_regression("helped_policy_there:make", "rule", **arguments)
    (tmp_path / "stealth_cfg2.py").write_text("ACTION = 4\n")
    with pytest.raises(ResumeMismatchError, match=r"stealth_cfg2\.py beside helped_policy_there \(SHA-256\)"):
        run_regression("helped_policy_there:make", "rule", **arguments)


def test_degenerate_episode_settings_are_refused_before_any_episode(tmp_path, capsys):
    out = tmp_path / "out"
    for config, stall, message in (('{"duration": -5}', "1", "config['duration'] is -5; it must be a number of seconds > 0"),
                                   ('{"duration": 0}', "1", "config['duration'] is 0; it must be a number of seconds > 0"),
                                   ('{"duration": 4}', "5", "--stall-seconds 5 is not shorter than the episodes (4 s)"),
                                   ('{"duration": 4}', "4", "--stall-seconds 4 is not shorter than the episodes (4 s)"),
                                   ('{"durration": 4}', "1", "unknown config key(s) 'durration' (did you mean 'duration'?)")):
        assert regress("--policy", "rule", "--baseline", "rule", "--scenarios", SCENARIO, "--config", config,
                       "--stall-seconds", stall, "--out", str(out), "--no-progress") == 2, config
        assert message in capsys.readouterr().err, config
        assert not out.exists()  # refused before any episode or output
    # without stall among the failure kinds a short episode is fine
    from dv2s_gym.regress.runner import _check_env_config

    from envs.safety_metrics import MonitorSettings

    _check_env_config({"duration": 2}, ["collision", "off_road"], MonitorSettings(stall_seconds=5.0))


def test_a_policy_option_of_the_wrong_type_is_named():
    with pytest.raises(PolicyError, match="action_noise must be a number, not 'abc'"):
        load_policy("rule?action_noise=abc")
    with pytest.raises(PolicyError, match="noise_seed must be an integer, not 1.5"):
        load_policy("rule?action_noise=0.1&noise_seed=1.5")
    assert load_policy("rule?action_noise=0.1&noise_seed=3").base_seed == 3


def test_a_run_against_a_baseline_report_repeats_its_seed_env_config_and_failure_kinds_unless_given(tmp_path):
    from dv2s_gym.regress.report import baseline_defaults

    path = tmp_path / "report.json"
    path.write_text(json.dumps({"schema": "dv2s-regress", "schema_version": 4,
                                "settings": {"seed": 7, "env_config": {"duration": 4}, "failure": ["collision", "stall"]}}))
    kinds = ["collision", "stall"]
    assert baseline_defaults(path, None, None) == (7, {"duration": 4}, kinds)
    assert baseline_defaults(path, 2, None) == (2, {"duration": 4}, kinds)
    assert baseline_defaults(path, None, {"duration": 9}) == (7, {"duration": 9}, kinds)
    assert baseline_defaults(path, 2, {}, "off_road") == (2, {}, "off_road")
    # all given: the report is not read (a missing one is refused later, by the run itself)
    assert baseline_defaults(tmp_path / "missing.json", 1, {}, "collision") == (1, {}, "collision")


def test_unknown_kinds_taken_from_a_baseline_report_name_the_report_its_plugins_and_the_fix(tmp_path, capsys):
    path = tmp_path / "report.json"
    judged = {kind: {"failure type": module, "detector": module, "sources (SHA-256)": {module: "a" * 64}}
              for kind, module in (("speeding", "myfail"), ("speeding2", "myfail2"))}
    path.write_text(json.dumps({"schema": "dv2s-regress", "schema_version": 4,
                                "code_identity": {"detectors": judged},
                                "settings": {"seed": 0, "env_config": {}, "failure": ["speeding", "speeding2"]}}))
    assert main(["regress", "--policy", "idm", "--baseline-report", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--failure:" not in err
    assert (f"baseline report {path} was judged on failure kinds speeding, speeding2, unknown here (speeding: "
            "plug-in module myfail; speeding2: plug-in module myfail2); load them with DV2S_PLUGINS=myfail,myfail2, "
            "or pass --failure with kinds this run knows (collision, off_road, stall") in err
    assert not (tmp_path / "out").exists()
    # a --failure the user typed is the user's: an unknown one is still named as the option's
    assert main(["regress", "--policy", "idm", "--baseline-report", str(path), "--failure", "speeding",
                 "--out", str(tmp_path / "out")]) == 2
    assert "--failure: unknown failure kind 'speeding'" in capsys.readouterr().err
