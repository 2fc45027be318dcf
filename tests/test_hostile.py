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

import gzip
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from scenario_bank.bank import Bank, ScenarioRejectedError, Sidecar
from scenario_bank.precheck import PrecheckError, precheck_text
from scenario_bank.safety import UnsafeScenarioError, check_script
from scenario_bank.sandbox import SandboxError, SandboxLimits, run_in_sandbox, verify_script

HOSTILE = Path(__file__).parent / "hostile"
BANK_SCRIPTS = sorted((Path(__file__).resolve().parents[1] / "scenario_bank" / "scenarios").glob("*/scenario.scenic"))
MARKER = "/tmp/dv2s-hostile-marker"
CLASSES = {"private-attribute", "dunder-format", "builtins", "imports", "file-process-network", "resource-exhaustion",
           "env-object-graph", "param-path", "encoding", "parser-resource"}
REPO = Path(__file__).resolve().parents[1]
# Small limits keep the suite fast: a normal scenario needs about 2 s of CPU and 0.7 GiB of address space.
TEST_LIMITS = SandboxLimits(cpu_seconds=6, memory_bytes=1536 * 2**20, wall_seconds=40)
LIMIT_WORDS = {"cpu": "6 s CPU-time limit", "memory": "1.5 GiB memory limit", "iterations": "no scene sampled in",
               "recursion": "recursion limit"}


def hostile_bytes(path: Path) -> bytes:
    """A hostile file's bytes (``.scenic.gz``: the big ones, kept compressed)."""
    data = path.read_bytes()
    return gzip.decompress(data) if path.suffix == ".gz" else data


def _header(path_or_text, key: str) -> str:
    if isinstance(path_or_text, Path):  # any encoding: the header is ASCII (UTF-16's NULs dropped)
        path_or_text = hostile_bytes(path_or_text)[:4096].replace(b"\0", b"").decode("latin-1").lstrip("\xef\xbb\xbf\xff\xfe")
    match = re.search(rf"^# {key}: (\S+)", path_or_text, re.M)
    return match.group(1) if match else ""


def corpus(caught_by=None):
    files = sorted([*HOSTILE.glob("*.scenic"), *HOSTILE.glob("*.scenic.gz")])
    return [p for p in files if caught_by is None or _header(p, "caught-by") == caught_by]


def _stem(path: Path) -> str:
    return path.name.split(".")[0]


def hostile_text(path: Path, marker: Path) -> str:
    return path.read_text(encoding="utf-8").replace(MARKER, str(marker))


def test_corpus_covers_every_class_with_at_least_40_scripts():
    files = corpus()
    assert len(files) >= 100
    classes = [_header(p, "class") for p in files]
    assert set(classes) == CLASSES
    assert all(_header(p, "caught-by") in ("precheck", "safety", "sandbox") for p in files)
    assert all(_header(p, "limit") in LIMIT_WORDS for p in corpus("sandbox"))


@pytest.mark.parametrize("path", corpus("safety"), ids=_stem)
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
        bank.add(text, Sidecar(description="a hostile script", name="hostile"))
    assert caught.value.stage == "safety" and caught.value.findings
    assert len(Bank(bank.root)) == 0 and not (bank.root / "hostile").exists()
    assert not marker.exists()


@pytest.mark.slow
@pytest.mark.parametrize("path", corpus("sandbox"), ids=_stem)
def test_sandbox_limits_hold_with_the_safety_check_bypassed(path, tmp_path):
    text = path.read_text(encoding="utf-8")
    assert check_script(text) == [], "resource exhaustion is legal Scenic: the sandbox, not the allowlist, stops it"
    limit = _header(text, "limit")
    result = run_in_sandbox(text, name=path.stem, limits=TEST_LIMITS, max_sample_iterations=200)
    assert not result.ok and result.limit == limit, result
    assert LIMIT_WORDS[limit] in result.message


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in corpus("sandbox") if _header(p, "limit") in ("memory", "iterations")],
                         ids=lambda p: p.stem)
def test_bank_add_refuses_what_the_sandbox_stops_and_stays_unchanged(path, tmp_path, monkeypatch):
    # CPU-limit cases are covered above; these are the quick ones through the whole Bank.add path.
    # The iterations case spends ~5.5 s of CPU on 2000 rejected samples, so it keeps the default
    # CPU limit: a tight one would make the CPU limit, not the iteration cap, stop it on a busy machine.
    if _header(path, "limit") == "memory":
        monkeypatch.setenv("DV2S_SANDBOX_CPU", "6")
    monkeypatch.setenv("DV2S_SANDBOX_MEMORY_MB", "1536")
    # the wall-clock limit is only a backstop here: on a loaded machine a 40 s one fired before the iteration cap
    monkeypatch.setenv("DV2S_SANDBOX_WALL", "600")
    bank = Bank(tmp_path / "bank")
    with pytest.raises(ScenarioRejectedError, match="sandboxed check") as caught:
        bank.add(path.read_text(encoding="utf-8"), Sidecar(description="a hostile script", name="hostile"))
    assert caught.value.limit == _header(path, "limit")
    assert len(Bank(bank.root)) == 0 and not (bank.root / "hostile").exists()


@pytest.mark.slow
def test_an_infinite_loop_through_bank_add_names_the_cpu_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("DV2S_SANDBOX_CPU", "4")
    bank = Bank(tmp_path / "bank")
    text = (HOSTILE / "exhaust_top_level_loop.scenic").read_text(encoding="utf-8")
    with pytest.raises(ScenarioRejectedError, match="exceeded the 4 s CPU-time limit while compiling"):
        bank.add(text, Sidecar(description="loops forever", name="loop"))
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


@pytest.mark.slow
def test_a_normal_script_passes_the_sandbox():
    assert len(BANK_SCRIPTS) >= 21
    text = BANK_SCRIPTS[0].read_text(encoding="utf-8")
    result = verify_script(text, name="normal", limits=TEST_LIMITS, use_cache=False)
    assert result.ok and not result.cached and result.stage == "done"
    assert result.timings["steps"] > 0 and set(result.timings) >= {"compile", "sample", "run"}


def test_the_child_gets_a_minimal_environment(monkeypatch):
    from scenario_bank.jail.bwrap import SCRATCH, worker_environment

    monkeypatch.setenv("OPENAI_API_KEY", "sk-secret")
    env = worker_environment()
    assert "OPENAI_API_KEY" not in env and not any("KEY" in k or "TOKEN" in k for k in env)
    assert env["HOME"].startswith(SCRATCH) and env["OMP_NUM_THREADS"] == "1"


@pytest.mark.slow
def test_a_script_that_fails_to_compile_is_a_clear_sandbox_error():
    text = BANK_SCRIPTS[0].read_text(encoding="utf-8") + "\nbroken = UndefinedThing(3)\n"
    with pytest.raises(SandboxError, match="while compiling.*UndefinedThing") as caught:
        verify_script(text, name="broken", limits=TEST_LIMITS)
    assert caught.value.stage == "compile" and caught.value.limit is None
    assert "/tmp/scenarios" not in str(caught.value)  # the jail's copy is named as the caller named the script


def test_path_methods_on_the_map_are_refused_and_a_local_map_still_compiles(tmp_path):
    # With the map a pathlib.Path, `replace` would move the map file anywhere: the name is refused on any object.
    shutil.copy(REPO / "scenario_bank" / "maps" / "highway_straight.xodr", tmp_path / "road.xodr")
    marker = tmp_path / "moved"
    body = "lane = Uniform(*network.lanes)\nego = new Car at lane.centerline.pointAlongBy(Range(100, 500))\n"
    head = "param map = localPath('road.xodr')\nmodel scenic.domains.driving.model\n"
    hostile = head + f"moved = globalParameters.map.replace({str(marker)!r})\n" + body
    assert {f.construct for f in check_script(hostile)} == {"globalParameters.map", ".replace"}
    from envs.scenarios import compile_scenario

    with pytest.raises(UnsafeScenarioError):
        compile_scenario(hostile, path=str(tmp_path / "local_map.scenic"), trusted=True)  # the allowlist still runs
    script = tmp_path / "fine.scenic"
    script.write_text(head + body, encoding="utf-8")
    compiled = compile_scenario(script.read_text(encoding="utf-8"), path=str(script), trusted=True)
    assert compiled.map_path.endswith("road.xodr") and (tmp_path / "road.xodr").is_file() and not marker.exists()


def test_the_text_compiled_is_the_text_checked_not_the_file_swapped_in_after(tmp_path):
    """A script given as a path is read once: swapping the file between the check and the compile
    changes nothing (Scenic compiles the checked text; localPath still resolves in the file's folder)."""
    from envs.scenarios import compile_scenario, read_scenario_file

    shutil.copy(REPO / "scenario_bank" / "maps" / "highway_straight.xodr", tmp_path / "road.xodr")
    script = tmp_path / "swap.scenic"
    script.write_text("param map = localPath('road.xodr')\nmodel scenic.domains.driving.model\nchecked = 1\n"
                      "lane = Uniform(*network.lanes)\nego = new Car at lane.centerline.pointAlongBy(Range(100, 500))\n",
                      encoding="utf-8")
    text = read_scenario_file(script)
    assert check_script(text) == []
    marker = tmp_path / "swapped-ran"
    script.write_text(hostile_text(HOSTILE / "file_localpath_touch.scenic", marker), encoding="utf-8")
    compiled = compile_scenario(text, path=str(script), trusted=True)
    assert compiled.source == text and compiled.map_path.endswith("road.xodr")
    compiled.sample(0)
    assert not marker.exists()


@pytest.mark.parametrize("path", corpus("precheck"), ids=_stem)
def test_the_precheck_refuses_before_any_parse(path, tmp_path):
    data = hostile_bytes(path)
    with pytest.raises(PrecheckError, match=r"failed the safety check: line \d+: .+: .{20,}") as caught:
        precheck_text(data, path.name)
    assert isinstance(caught.value, UnsafeScenarioError) and len(caught.value.findings) == 1
    assert check_script(data) == caught.value.findings  # check_script runs it first, and parses nothing more
    script = tmp_path / "hostile.scenic"
    script.write_bytes(data)
    from envs.dv2s_env import DV2SEnv

    with pytest.raises(UnsafeScenarioError, match="failed the safety check"):
        DV2SEnv(scenario=str(script)).reset(seed=0)


_CHECK_IN_CHILD = """
import gzip, sys
from scenario_bank.safety import check_script
data = open(sys.argv[1], "rb").read()
findings = check_script(gzip.decompress(data) if sys.argv[1].endswith(".gz") else data)
print(len(findings), findings[0] if findings else "")
"""


@pytest.mark.slow
@pytest.mark.parametrize("path", corpus("precheck") + corpus("safety"), ids=_stem)
def test_every_refusal_takes_bounded_time(path):
    # A child process with a timeout: a parser that hangs or crashes shows as a failure, not a hung suite.
    done = subprocess.run([sys.executable, "-c", _CHECK_IN_CHILD, str(path)], cwd=REPO, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert int(done.stdout.split()[0]) > 0, done.stdout


def test_every_shipped_and_corpus_script_passes_the_precheck():
    scripts = [p for p in REPO.rglob("*.scenic") if HOSTILE not in p.parents and ".venv" not in p.parts]
    assert len(scripts) >= 100
    for path in scripts:
        precheck_text(path.read_bytes(), str(path))


def test_env_attributes_cover_the_envs_and_simulators_own_names():
    """ENV_ATTRIBUTES is the public attributes of the env, simulator, Gymnasium and highway-env classes,
    minus generic names and those Scenic's driving domain also defines: recompute and compare."""
    import dataclasses

    import gymnasium as gym
    from gymnasium.envs.registration import EnvSpec
    from highway_env.envs.common.abstract import AbstractEnv
    from scenic.core.simulators import Simulation, Simulator

    from envs.dv2s_env import DV2SEnv
    from envs.scenic_highway.simulator import HighwayEnvSimulator
    from scenario_bank.safety import ENV_ATTRIBUTES

    handles = {f.name for f in dataclasses.fields(EnvSpec)}
    for cls in (gym.Env, gym.Wrapper, EnvSpec, AbstractEnv, Simulator, Simulation, DV2SEnv, HighwayEnvSimulator):
        handles |= {name for name in dir(cls) if not name.startswith("_")}
    generic = {"id", "name", "version", "namespace", "class_name", "trace", "PERCEPTION_DISTANCE",
               "currentRealTime", "valuesHaveDiverged", "actionsAreCompatible", "detectReplayEnd",
               "replayCanContinue"}
    assert handles - generic <= ENV_ATTRIBUTES


@pytest.mark.parametrize("path", corpus("safety"), ids=_stem)
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
    fine = ("param map = 'highway_straight'\nparam sumo_map = localPath('maps/Town01.net.xml')\n"
            "model scenic.domains.driving.model\nfor _ in range(3):\n    pass\nego = new Car\n")
    assert check_script(fine) == []
    hostile = ("param map = 'highway_straight'\nparam sumo_map = localPath('x')\nmodel scenic.domains.driving.model\n"
               "globalParameters.sumo_map.touch()\nhere = localPath('y')\n_.__class__\n_x = 1\nego = new Car\n")
    assert sorted(f.construct for f in check_script(hostile)) == [".__class__", ".touch", "_x", "globalParameters.sumo_map",
                                                                 "localPath"]


def test_a_trusted_hand_written_script_still_gets_the_allowlist_check_in_the_words_of_any_script(tmp_path):
    """`--trusted` skips the jail, not the check; the refusal speaks of every script dv2s-gym runs, and
    --trusted's help says what it skips and what it does not."""
    from dv2s_gym.cli import build_parser
    from envs.dv2s_env import DV2SEnv

    script = tmp_path / "mine.scenic"
    script.write_text("import os\n" + (BANK_SCRIPTS[0]).read_text(encoding="utf-8"), encoding="utf-8")
    with pytest.raises(UnsafeScenarioError) as caught:
        DV2SEnv(scenario=str(script), trusted=True).reset(seed=0)
    message = str(caught.value)
    assert "Scenic scripts run by dv2s-gym may only use" in message and "Generated" not in message
    assert "the check applies to every script, trusted or not" in message and "\n" not in message
    run = next(a for a in build_parser()._actions if a.dest == "command").choices["run"]
    trusted = next(a.help for a in run._actions if "--trusted" in a.option_strings)
    assert "skipping the jail" in trusted and "does not skip the allowlist check" in trusted
