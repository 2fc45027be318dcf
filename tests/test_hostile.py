"""The sandbox holds: every script of the hostile corpus is refused, none is executed, the bank is unchanged.

Each ``tests/hostile/*.scenic`` says in its header which class of attack it is,
which layer must stop it (``caught-by: safety`` or ``sandbox``) and, for
resource exhaustion, which limit (``cpu``, ``memory``, ``iterations``,
``recursion``). Payloads that touch the file system write the marker path
``/tmp/dv2s-hostile-marker``, which every test replaces by a path of its own
and checks never exists. Resource-exhaustion scripts pass the allowlist (they
are legal Scenic), so they run in the sandbox directly, with small limits, to
prove the limits hold.
"""

import re
import shutil
from pathlib import Path

import pytest

from scenario_bank.bank import Bank, ScenarioRejectedError
from scenario_bank.safety import UnsafeScenarioError, check_script
from scenario_bank.sandbox import SandboxError, SandboxLimits, run_in_sandbox, verify_script

HOSTILE = Path(__file__).parent / "hostile"
BANK_SCRIPTS = sorted((Path(__file__).resolve().parents[1] / "scenario_bank" / "scenarios").glob("*/scenario.scenic"))
MARKER = "/tmp/dv2s-hostile-marker"
CLASSES = {"private-attribute", "dunder-format", "builtins", "imports", "file-process-network", "resource-exhaustion"}
# Small limits keep the suite fast: a normal scenario needs about 2 s of CPU and 0.7 GiB of address space.
TEST_LIMITS = SandboxLimits(cpu_seconds=6, memory_bytes=1536 * 2**20, wall_seconds=40)
LIMIT_WORDS = {"cpu": "6 s CPU-time limit", "memory": "1.5 GiB memory limit", "iterations": "no scene sampled in",
               "recursion": "recursion limit"}


def _header(text: str, key: str) -> str:
    match = re.search(rf"^# {key}: (\S+)", text, re.M)
    return match.group(1) if match else ""


def corpus(caught_by=None):
    files = sorted(HOSTILE.glob("*.scenic"))
    return [p for p in files if caught_by is None or _header(p.read_bytes().decode("utf-8", "replace"), "caught-by") == caught_by]


def hostile_text(path: Path, marker: Path) -> str:
    return path.read_text(encoding="utf-8").replace(MARKER, str(marker))


def test_corpus_covers_every_class_with_at_least_40_scripts():
    files = corpus()
    assert len(files) >= 40
    classes = [_header(p.read_bytes().decode("utf-8", "replace"), "class") for p in files]
    assert set(classes) == CLASSES
    assert all(_header(p.read_bytes().decode("utf-8", "replace"), "caught-by") in ("safety", "sandbox") for p in files)
    assert all(_header(p.read_bytes().decode("utf-8", "replace"), "limit") in LIMIT_WORDS for p in corpus("sandbox"))


@pytest.mark.parametrize("path", corpus("safety"), ids=lambda p: p.stem)
def test_safety_check_refuses_with_line_and_reason(path, tmp_path):
    marker = tmp_path / "marker"
    text = hostile_text(path, marker)
    findings = check_script(text)
    assert findings, f"{path.name} passed the safety check"
    assert all(f.line > 0 and f.construct and len(f.reason) > 20 for f in findings)
    with pytest.raises(UnsafeScenarioError, match=r"failed the safety check: line \d+"):
        verify_script(text, name=path.stem, limits=TEST_LIMITS)
    bank = Bank(tmp_path / "bank")
    with pytest.raises(ScenarioRejectedError, match="safety check") as caught:
        bank.add(text, "a hostile script", name="hostile")
    assert caught.value.stage == "safety" and caught.value.findings
    assert len(Bank(bank.root)) == 0 and not (bank.root / "hostile").exists()
    assert not marker.exists()


@pytest.mark.parametrize("path", corpus("sandbox"), ids=lambda p: p.stem)
def test_sandbox_limits_hold_with_the_safety_check_bypassed(path, tmp_path):
    text = path.read_text(encoding="utf-8")
    assert check_script(text) == [], "resource exhaustion is legal Scenic: the sandbox, not the allowlist, stops it"
    limit = _header(text, "limit")
    result = run_in_sandbox(text, name=path.stem, limits=TEST_LIMITS, max_sample_iterations=200)
    assert not result.ok and result.limit == limit, result
    assert LIMIT_WORDS[limit] in result.message


@pytest.mark.parametrize("path", [p for p in corpus("sandbox") if _header(p.read_bytes().decode("utf-8", "replace"), "limit") in ("memory", "iterations")],
                         ids=lambda p: p.stem)
def test_bank_add_refuses_what_the_sandbox_stops_and_stays_unchanged(path, tmp_path, monkeypatch):
    # CPU-limit cases are covered above; these are the quick ones through the whole Bank.add path.
    # The iterations case spends ~5.5 s of CPU on 2000 rejected samples, so it keeps the default
    # CPU limit: a tight one would make the CPU limit, not the iteration cap, stop it on a busy machine.
    if _header(path.read_bytes().decode("utf-8", "replace"), "limit") == "memory":
        monkeypatch.setenv("DV2S_SANDBOX_CPU", "6")
    monkeypatch.setenv("DV2S_SANDBOX_MEMORY_MB", "1536")
    monkeypatch.setenv("DV2S_SANDBOX_WALL", "40")
    bank = Bank(tmp_path / "bank")
    with pytest.raises(ScenarioRejectedError, match="sandboxed check") as caught:
        bank.add(path.read_text(encoding="utf-8"), "a hostile script", name="hostile")
    assert caught.value.limit == _header(path.read_bytes().decode("utf-8", "replace"), "limit")
    assert len(Bank(bank.root)) == 0 and not (bank.root / "hostile").exists()


def test_an_infinite_loop_through_bank_add_names_the_cpu_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("DV2S_SANDBOX_CPU", "4")
    bank = Bank(tmp_path / "bank")
    text = (HOSTILE / "exhaust_top_level_loop.scenic").read_text(encoding="utf-8")
    with pytest.raises(ScenarioRejectedError, match="exceeded the 4 s CPU-time limit while compiling"):
        bank.add(text, "loops forever", name="loop")
    assert len(Bank(bank.root)) == 0


def test_the_issues_reproduction_is_refused_by_the_cli(tmp_path, capsys):
    from dv2s_gym.cli import main

    marker = tmp_path / "pwned"
    script = tmp_path / "evil.scenic"
    script.write_text(hostile_text(HOSTILE / "private_random_os.scenic", marker))
    code = main(["bank", "--bank", str(tmp_path / "bank"), "add", str(script), "--description", "evil"])
    assert code != 0
    err = capsys.readouterr().err
    assert "import random" in err and "safety check" in err
    assert not marker.exists() and len(Bank(tmp_path / "bank")) == 0


@pytest.mark.parametrize("path", BANK_SCRIPTS, ids=lambda p: p.parent.name)
def test_every_bank_script_passes_the_safety_check(path):
    assert check_script(path.read_text(encoding="utf-8")) == []


def test_a_normal_script_passes_the_sandbox():
    assert len(BANK_SCRIPTS) >= 21
    text = BANK_SCRIPTS[0].read_text(encoding="utf-8")
    result = verify_script(text, name="normal", limits=TEST_LIMITS, use_cache=False)
    assert result.ok and not result.cached and result.stage == "done"
    assert result.timings["steps"] > 0 and set(result.timings) >= {"compile", "sample", "run"}


def test_the_child_gets_a_minimal_environment(monkeypatch):
    from scenario_bank.sandbox import _minimal_env

    monkeypatch.setenv("OPENAI_API_KEY", "sk-secret")
    env = _minimal_env("/tmp/x")
    assert "OPENAI_API_KEY" not in env and not any("KEY" in k or "TOKEN" in k for k in env)
    assert env["HOME"] == "/tmp/x" and env["OMP_NUM_THREADS"] == "1"


def test_a_script_that_fails_to_compile_is_a_clear_sandbox_error():
    text = BANK_SCRIPTS[0].read_text(encoding="utf-8") + "\nbroken = UndefinedThing(3)\n"
    with pytest.raises(SandboxError, match="while compiling.*UndefinedThing") as caught:
        verify_script(text, name="broken", limits=TEST_LIMITS)
    assert caught.value.stage == "compile" and caught.value.limit is None


def test_a_local_path_map_reaches_the_script_as_a_plain_string(tmp_path):
    # Legal Scenic (it passes the check): with the map a pathlib.Path, `replace` would move the map file anywhere.
    shutil.copy(Path(__file__).resolve().parents[1] / "scenario_bank" / "maps" / "highway_straight.xodr",
                tmp_path / "road.xodr")
    marker = tmp_path / "moved"
    script = tmp_path / "local_map.scenic"
    script.write_text(
        "param map = localPath('road.xodr')\nmodel scenic.domains.driving.model\n"
        f"moved = globalParameters.map.replace({str(marker)!r})\n"
        "lane = Uniform(*network.lanes)\nego = new Car at lane.centerline.pointAlongBy(Range(100, 500))\n",
        encoding="utf-8")
    text = script.read_text(encoding="utf-8")
    assert check_script(text) == []
    from envs.errors import ScenarioCompileError
    from envs.scenarios import compile_scenario

    with pytest.raises(ScenarioCompileError, match="replace expected at least 2 arguments"):
        compile_scenario(text, path=str(script))  # str.replace, not Path.replace
    assert (tmp_path / "road.xodr").is_file() and not marker.exists()


@pytest.mark.parametrize("path", corpus("safety"), ids=lambda p: p.stem)
def test_the_env_refuses_unsafe_scripts_before_compiling(path, tmp_path):
    # a user's own file or text given to gym.make / `dv2s run` is checked too, not only bank additions
    from envs.dv2s_env import DV2SEnv

    marker = tmp_path / "marker"
    script = tmp_path / "hostile.scenic"
    script.write_text(hostile_text(path, marker), encoding="utf-8")
    for scenario in (str(script), script.read_text(encoding="utf-8")):
        with pytest.raises(UnsafeScenarioError, match="failed the safety check"):
            DV2SEnv(scenario=scenario).reset(seed=0)
    assert not marker.exists()


def test_foreign_script_idioms_pass_but_what_they_could_reach_stays_refused():
    """A throwaway `_` and `param sumo_map = localPath(...)` (Scenic's CARLA/MetaDrive examples) are
    allowed; private attributes on `_`, file methods on such a parameter and a free localPath are not."""
    fine = ("param map = 'highway_straight'\nparam sumo_map = localPath('../maps/Town01.net.xml')\n"
            "model scenic.domains.driving.model\nfor _ in range(3):\n    pass\nego = new Car\n")
    assert check_script(fine) == []
    hostile = ("param map = 'highway_straight'\nparam sumo_map = localPath('x')\nmodel scenic.domains.driving.model\n"
               "globalParameters.sumo_map.touch()\nhere = localPath('y')\n_.__class__\n_x = 1\nego = new Car\n")
    assert sorted(f.construct for f in check_script(hostile)) == [".__class__", ".touch", "_x", "localPath"]
