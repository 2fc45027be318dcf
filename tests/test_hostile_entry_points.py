"""Hostile scripts through every door a user opens: the CLI, a bank folder (validate, sample, gym.make by
name, mining), an archive import and the LLM generator. Each is refused or contained: no marker file
written, a canary API key in the environment never shown, the user's process neither crashes nor hangs,
and no process of the jail is left behind.

One script per class of the corpus that reaches the interpreter or the machine (object-graph walks,
files/processes/network, path-typed parameters) and one the allowlist cannot stop (resource exhaustion,
contained by the jail's limits).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HOSTILE = ROOT / "tests" / "hostile"
MARKER = "/tmp/dv2s-hostile-marker"
CANARY = "sk-canary-4417-entry-points"
SHIPPED = ROOT / "scenario_bank" / "scenarios" / "highway_lead_vehicle_brakes"

SCRIPTS = ["env_spec_make", "file_open_write", "param_value_path_methods", "exhaust_memory_growth"]


def _script(name: str, marker: Path) -> str:
    matches = sorted(HOSTILE.glob(f"{name}*.scenic"))
    assert matches, f"no hostile script {name}"
    return matches[0].read_text(encoding="utf-8").replace(MARKER, str(marker))


def _bank_with(folder: Path, text: str) -> Path:
    """A bank folder whose entry ``hostile`` holds ``text`` with a consistent sidecar (as if written by hand)."""
    entry = folder / "hostile"
    entry.mkdir(parents=True)
    (entry / "scenario.scenic").write_text(text, encoding="utf-8")
    meta = json.loads((SHIPPED / "meta.json").read_text(encoding="utf-8"))
    meta["content_hash"] = hashlib.sha256(text.encode("utf-8")).hexdigest()
    meta["name"] = "hostile"
    (entry / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
    return folder


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "OPENAI_API_KEY": CANARY, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def _jail_processes() -> set:
    """Jail processes that descend from this process (the CLI's own die with it: bubblewrap's --die-with-parent)."""
    parents, commands = {}, {}
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            commands[int(pid)] = Path(f"/proc/{pid}/cmdline").read_bytes()
            stat = Path(f"/proc/{pid}/stat").read_text()
            parents[int(pid)] = int(stat.rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue

    def ours(pid: int) -> bool:
        seen = set()
        while pid not in seen and pid > 1:
            seen.add(pid)
            if pid == os.getpid():
                return True
            pid = parents.get(pid, 0)
        return False

    return {pid for pid, command in commands.items()
            if (b"bwrap" in command or b"jail_worker" in command or b"zygote_server" in command)
            and ours(parents.get(pid, 0))}


@pytest.fixture
def no_leftovers():
    from scenario_bank.jail.process import discard_spares  # also stops the zygote, which outlives envs

    before = _jail_processes()
    yield
    discard_spares()
    import time

    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and _jail_processes() - before:
        time.sleep(0.2)
    assert _jail_processes() - before == set()


def _no_canary(*texts: str) -> None:
    for text in texts:
        assert CANARY not in (text or "")


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_a_hostile_script_is_refused_or_contained_at_every_entry_point(name, tmp_path, monkeypatch, no_leftovers):
    import gymnasium as gym

    import dv2s_gym  # noqa: F401
    from scenario_bank.bank import Bank
    from scenario_bank.bank import ScenarioRejectedError

    monkeypatch.setenv("OPENAI_API_KEY", CANARY)
    marker = tmp_path / "marker"
    text = _script(name, marker)
    script = tmp_path / "hostile.scenic"
    script.write_text(text, encoding="utf-8")

    # dv2s run <path>: one clear error, exit code not 0
    run = _cli("run", str(script), "--video", str(tmp_path / "out.webm"), "--duration", "2")
    assert run.returncode != 0 and "Traceback" not in run.stderr, run.stderr[-2000:]
    _no_canary(run.stdout, run.stderr)

    # gym.make with the text and with the path
    for scenario in (text, str(script)):
        with pytest.raises(Exception) as caught:
            env = gym.make("dv2s_gym:DV2S-v0", scenario=scenario, config={"duration": 2.0})
            try:
                env.reset(seed=0)
                for _ in range(10):
                    env.step(1)
            finally:
                env.close()
        _no_canary(str(caught.value))

    # a bank folder holding it: validate names it, gym.make by name refuses it, mining runs nothing of it here
    bank_dir = _bank_with(tmp_path / "bank", text)
    validate = _cli("bank", "--bank", str(bank_dir), "validate")
    assert validate.returncode == 1 and "hostile" in validate.stdout + validate.stderr
    _no_canary(validate.stdout, validate.stderr)
    sample = _cli("bank", "--bank", str(bank_dir), "sample", "--count", "2")
    _no_canary(sample.stdout, sample.stderr)
    with pytest.raises(Exception):
        env = gym.make("dv2s_gym:DV2S-v0", scenario="hostile", bank_dir=str(bank_dir), config={"duration": 2.0})
        try:
            env.reset(seed=0)
            env.step(1)
        finally:
            env.close()
    mine = _cli("mine", "--bank", str(bank_dir), "--scenarios", "hostile", "--policy", "keep_lane", "--budget", "2",
                "--workers", "1", "--out", str(tmp_path / "mine"))
    _no_canary(mine.stdout, mine.stderr)
    assert "Traceback" not in mine.stderr, mine.stderr[-2000:]

    # an archive of it: the import refuses it and leaves the target bank as it was
    archive = Bank(bank_dir).export(tmp_path / "hostile.tar.gz")
    target = Bank(tmp_path / "target")
    with pytest.raises((ScenarioRejectedError, ValueError)):
        target.import_archive(archive)
    assert Bank(tmp_path / "target").names() == []

    assert not marker.exists()


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_an_llm_that_answers_with_a_hostile_script_gets_no_scenario(name, tmp_path, monkeypatch, no_leftovers):
    sys.path.insert(0, str(ROOT / "tests"))
    import llm_server
    from llm_server import ChatServer

    from dv2s_gym.pipeline.llm_client import ChatClient
    from dv2s_gym.pipeline.sg.openai import ExampleRetriever, bank_examples, generate_with_llm

    monkeypatch.setenv("OPENAI_API_KEY", CANARY)
    marker = tmp_path / "marker"
    body = json.loads((llm_server.DATA / "sg_lead_brake_scenic2.json").read_text(encoding="utf-8"))
    body["choices"][0]["message"]["content"] = "Here it is:\n\n```scenic\n" + _script(name, marker) + "\n```\n"
    data = tmp_path / "llm"
    data.mkdir()
    (data / "hostile.json").write_text(json.dumps(body), encoding="utf-8")
    monkeypatch.setattr(llm_server, "DATA", data)
    with ChatServer(default="hostile.json") as server:
        client = ChatClient(server.base_url, "gpt-4o", timeout=5, retries=1)
        result = generate_with_llm("A lead car brakes hard on a highway.", client, max_attempts=2, k=1,
                                   retriever=ExampleRetriever(bank_examples(), backend="tfidf"),
                                   max_sample_iterations=200, raise_on_failure=False)
    assert not result.ok and result.failures
    failures = [f.to_dict() for f in result.failures]
    assert all(f["stage"] in ("safety", "compile", "sample", "run") for f in failures), failures
    _no_canary(*(str(f.get("message")) for f in failures))
    assert not marker.exists()
    shutil.rmtree(data)
