"""Scenic 2 -> 3 upgrader: rules, idempotence, the real Scenic 2 corpus, and its three users."""

import json
import subprocess
import textwrap
import warnings
from pathlib import Path

import pytest

from scenario_bank.scenic2 import looks_like_scenic2, upgrade_scenic2

pytestmark = pytest.mark.usefixtures("in_process_simulator")

ROOT = Path(__file__).resolve().parents[1]
CORPUS = sorted((ROOT / "tests" / "data" / "scenic2").glob("*.scenic"))
TOWN01 = str(ROOT / "tests" / "data" / "maps" / "CARLA" / "Town01.xodr")

# a Scenic 2 script on the env's own model (no `new`, bare statement creation, old monitor)
HIGHWAY_SCENIC2 = textwrap.dedent(
    """\
    param map = 'highway_straight'
    model scenic.domains.driving.model
    lane = Uniform(*network.lanes)
    ego = Car at lane.centerline.pointAlongBy(Range(100, 500)),
        with speed 20
    Car following roadDirection from ego for 25,
        with behavior FollowLaneBehavior(target_speed=15)
    """
)


def test_bare_creation_gets_new_everywhere_it_creates():
    source = textwrap.dedent(
        """\
        ego = Car at (0, 0)   # Car here is a comment
        Car ahead of ego by 10
        spot = OrientedPoint on curb
        p = (Point on road).position
        cars = [Car behind ego, Car left of ego]
        name = "Car at (1, 2)"
        lone = Car
        def f():
            return Pedestrian
        """
    )
    upgrade = upgrade_scenic2(source)
    assert upgrade.source == textwrap.dedent(
        """\
        ego = new Car at (0, 0)   # Car here is a comment
        new Car ahead of ego by 10 - ego.length / 2
        spot = new OrientedPoint on curb
        p = (new Point on road).position
        cars = [new Car behind ego by -ego.length / 2, new Car left of ego by -ego.width / 2]
        name = "Car at (1, 2)"
        lone = new Car
        def f():
            return new Pedestrian
        """
    )
    assert [r.line for r in upgrade.rewrites] == [1, 2, 3, 4, 5, 7, 9]
    assert upgrade.rewrites[4].after.strip() == ("cars = [new Car behind ego by -ego.length / 2, "
                                                 "new Car left of ego by -ego.width / 2]")
    assert all("new" in r.why for r in upgrade.rewrites)
    assert "from ego's edge, Scenic 2 from its centre" in upgrade.rewrites[1].why
    assert any("requireVisible" in n for n in upgrade.notes)


def test_references_to_classes_are_not_creations():
    source = textwrap.dedent(
        """\
        class Cone(Object):
            width: 0.3
        ok = isinstance(ego, Car)
        kinds = (Car, Truck)
        speed = Car.defaultSpeed if x else 0
        require (distance to Car) > 3
        """
    )
    upgrade = upgrade_scenic2(source)
    assert upgrade.source == source and upgrade.rewrites == []


def test_script_classes_multiline_specifiers_and_behaviours():
    source = textwrap.dedent(
        """\
        class Cone(Object):
            width: 0.3
        behavior Wait():
            while True:
                wait
        Cone at (5, 0),
            facing 10 deg
        ego = Car with behavior Wait(),
            with speed 3
        """
    )
    upgrade = upgrade_scenic2(source)
    assert "new Cone at (5, 0)," in upgrade.source and "ego = new Car with behavior Wait()," in upgrade.source
    assert [r.line for r in upgrade.rewrites] == [6, 8]


def test_old_monitor_gets_parentheses_and_a_require():
    source = "ego = new Object\nmonitor Stop:\n    wait\n    terminate\n"
    upgrade = upgrade_scenic2(source)
    assert upgrade.source == "ego = new Object\nmonitor Stop():\n    wait\n    terminate\nrequire monitor Stop()\n"
    assert [(r.line, r.after) for r in upgrade.rewrites] == [(2, "monitor Stop():"), (5, "require monitor Stop()")]
    assert upgrade_scenic2(upgrade.source).rewrites == []


def test_what_it_cannot_translate_is_reported_not_mangled():
    broken = "ego = Car at (0, 0\n"  # unclosed parenthesis: the tokenizer cannot read it
    upgrade = upgrade_scenic2(broken)
    assert upgrade.source == broken and upgrade.rewrites == []
    assert len(upgrade.notes) == 1 and "cannot be tokenized" in upgrade.notes[0]
    nested = "scenario Main():\n    setup:\n        ego = new Object\n    monitor Old:\n        wait\n"
    upgrade = upgrade_scenic2(nested)
    assert upgrade.source == nested
    assert any("line 4: not translated" in n and "'Old'" in n for n in upgrade.notes)


def test_looks_like_scenic2_uses_syntax_and_the_compile_error():
    assert looks_like_scenic2(HIGHWAY_SCENIC2)
    assert looks_like_scenic2(HIGHWAY_SCENIC2, "ScenicParseError: invalid syntax")
    assert not looks_like_scenic2(HIGHWAY_SCENIC2, "name 'leadGap' is not defined")
    assert not looks_like_scenic2(upgrade_scenic2(HIGHWAY_SCENIC2).source)
    assert not looks_like_scenic2("# ego = Car at (0, 0)\nego = new Car\n")


def test_every_repo_script_is_unchanged():
    files = subprocess.run(["git", "ls-files", "*.scenic"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    # not the Scenic 2 corpora (ours, tests/data/carla_corpus), nor the hostile files built to break readers
    files = [f for f in files if "/scenic2/" not in f and not f.startswith("tests/hostile/")]
    assert len(files) > 20
    changed = [f for f in files if upgrade_scenic2((ROOT / f).read_text()).rewrites]
    assert changed == []


@pytest.mark.slow
@pytest.mark.parametrize("path", CORPUS, ids=[p.name for p in CORPUS])
def test_corpus_script_upgrades_to_compiling_scenic3(path):
    import scenic

    source = path.read_text()
    with pytest.raises(Exception):  # as published it is not Scenic 3
        scenic.scenarioFromString(source, params={"map": TOWN01}, mode2D=True)
    upgrade = upgrade_scenic2(source)
    assert upgrade.rewrites and looks_like_scenic2(source)
    scenic.scenarioFromString(upgrade.source, params={"map": TOWN01}, mode2D=True)
    again = upgrade_scenic2(upgrade.source)
    assert again.source == upgrade.source and again.rewrites == []


def test_corpus_is_all_listed_in_sources():
    sources = (ROOT / "tests" / "data" / "scenic2" / "SOURCES.md").read_text()
    assert len(CORPUS) >= 10 and all(f"| {p.name} |" in sources for p in CORPUS)


def test_env_upgrades_on_request_and_runs(tmp_path):
    import gymnasium as gym

    from envs.errors import ScenarioCompileError

    script = tmp_path / "old.scenic"
    script.write_text(HIGHWAY_SCENIC2)
    with pytest.raises(ScenarioCompileError, match="line 5"):  # not upgraded unless asked
        gym.make("dv2s_gym:DV2S-v0", scenario=str(script), config={"duration": 1.0})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make("dv2s_gym:DV2S-v0", scenario=str(script), config={"upgrade_scenic2": True, "duration": 1.0})
        env.reset(seed=0)
    messages = [str(w.message) for w in caught if "scenic2" in str(w.message)]
    assert len(messages) == 1 and "line 4" in messages[0] and "line 6" in messages[0]
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(1)
    assert len(env.unwrapped.road.vehicles) == 2
    env.close()


def test_bank_add_upgrades_and_prints_rewrites(tmp_path, capsys):
    from cli_helpers import run

    script = tmp_path / "old.scenic"
    script.write_text(HIGHWAY_SCENIC2)
    code, out, err = run(capsys, "bank", "--bank", str(tmp_path / "bank"), "add", str(script),
                         "--description", "A car ahead.", "--name", "old", "--json")
    assert code == 0, err
    assert "scenic2: line 4:" in err and "scenic2: line 6:" in err
    entry = json.loads(out)
    assert entry["name"] == "old" and len(entry["scenic2_rewrites"]) == 2
    stored = Path(entry["path"]).read_text()
    assert "ego = new Car at" in stored and "\nnew Car following" in stored
    from scenario_bank.bank import Bank

    assert list(Bank(tmp_path / "bank").get("old").source.scenic2_rewrites) == entry["scenic2_rewrites"]


@pytest.mark.slow
def test_llm_repair_loop_upgrades_scenic2_without_a_repair_round():
    from llm_server import ChatServer, load_recorded

    from dv2s_gym.pipeline.llm_client import ChatClient
    from dv2s_gym.pipeline.sg.openai import ExampleRetriever, bank_examples, extract_scenic_block, generate_with_llm

    fixed = extract_scenic_block(load_recorded("sg_lead_brake_attempt2_fixed.json")["choices"][0]["message"]["content"])
    with ChatServer(default="sg_lead_brake_scenic2.json") as server:
        client = ChatClient(server.base_url, "gpt-4o", timeout=5, retries=3)
        result = generate_with_llm("A lead car brakes hard on a highway.", client,
                                   retriever=ExampleRetriever(bank_examples(), backend="tfidf"), k=1,
                                   max_sample_iterations=300)
    assert result.ok and result.attempts == 1 and server.request_count == 1 and result.failures == []
    assert result.script == fixed
    assert len(result.scenic2_rewrites) == 3 and all("new Car" in r for r in result.scenic2_rewrites)


# corpus scripts whose constructs DV2S-v0 provides: upgraded, with their map line swapped to the shipped
# urban_crossroads (the allowlist refuses their '../..' paths), they sample and run a few steps
RUNS_IN_ENV = ["badlyParkedCarPullingIn", "car", "carlaChallenge2", "carlaChallenge3", "oas_scenario_03",
               "oas_scenario_04", "pedestrianAcrossRoad", "iccv_2_agent_scenario"]


@pytest.mark.slow
@pytest.mark.parametrize("name", RUNS_IN_ENV)
def test_corpus_script_runs_in_dv2s_env_when_upgraded(name):
    import re

    import gymnasium as gym

    source = (ROOT / "tests" / "data" / "scenic2" / f"{name}.scenic").read_text()
    source = re.sub(r"^param map = .*$", "param map = 'urban_crossroads'", source, count=1, flags=re.M)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make("dv2s_gym:DV2S-v0", scenario=source,
                       config={"upgrade_scenic2": True, "duration": 1.0, "max_sample_iterations": 500})
        env.reset(seed=0)
    assert any("scenic2:" in str(w.message) for w in caught)
    for _ in range(3):
        env.step(1)
    assert env.unwrapped.road.vehicles
    env.close()
