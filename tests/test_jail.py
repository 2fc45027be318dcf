"""The jail for untrusted Scenic: what a script inside can and cannot do, and the thin client around it."""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time

import gymnasium as gym
import numpy as np
import pytest

from scenario_bank.jail import JailedProcess, JailLimits, JailProtocolError, jail_status
from scenario_bank.jail import bwrap, seccomp, wire

pytestmark = pytest.mark.skipif(not jail_status()[0], reason=f"no jail here: {jail_status()[1]}")

CANARY = "sk-dv2s-canary-0123456789"
SHIPPED = "highway_cut_in_from_left"


def _limit() -> None:
    import resource

    for which, soft, hard in JailLimits().rlimits():
        resource.setrlimit(which, (soft, hard))


def _probe(code: str, tmp_path) -> dict:
    """Run ``code`` (Python) in the exact jail the workers get; it prints one JSON line."""
    fd = seccomp.filter_fd()
    env = dict(os.environ, CANARY_API_KEY=CANARY)
    argv = bwrap.command([sys.executable, "-s", "-c", textwrap.dedent(code)], scratch_bytes=8 * 2**20,
                         seccomp_fd=fd, environment=bwrap.worker_environment())
    try:
        done = subprocess.run(argv, pass_fds=(fd,), env=env, capture_output=True, timeout=120, cwd=tmp_path,
                              preexec_fn=_limit)
    finally:
        os.close(fd)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    return json.loads(done.stdout.decode().strip().splitlines()[-1])


def test_jail_sees_no_environment_home_repo_or_parent(tmp_path):
    marker = tmp_path / "secret.txt"
    marker.write_text("top secret")
    result = _probe(f"""
        import json, os
        out = {{"env": dict(os.environ), "pid": os.getpid()}}
        def can_read(path):
            try:
                with open(path, "rb") as f:
                    return f.read(64) != b""
            except OSError:
                return False
        out["secret"] = can_read({str(marker)!r})
        out["readme"] = can_read({str(bwrap.CODE_ROOT / "README.md")!r})
        out["root_home"] = os.path.exists("/root/.bashrc") or os.path.exists(os.path.expanduser("~root/.ssh"))
        out["parent_environ"] = can_read("/proc/{os.getpid()}/environ")
        out["processes"] = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
        print(json.dumps(out))
    """, tmp_path)
    assert CANARY not in json.dumps(result["env"])
    assert set(result["env"]) <= set(bwrap.worker_environment()) | {"PWD"}
    assert not result["secret"] and not result["readme"] and not result["root_home"]
    assert not result["parent_environ"]
    assert len(result["processes"]) <= 3  # bubblewrap's init, the probe (and its own /proc entry)


def test_jail_refuses_processes_network_writes_and_tracing(tmp_path):
    result = _probe(f"""
        import ctypes, json, os, socket
        out = {{}}
        def attempt(name, call):
            try:
                call()
                out[name] = "allowed"
            except OSError as error:
                out[name] = "refused"
        attempt("fork", os.fork)
        attempt("inet", lambda: socket.socket(socket.AF_INET, socket.SOCK_STREAM))
        attempt("inet6", lambda: socket.socket(socket.AF_INET6, socket.SOCK_DGRAM))
        attempt("write_outside", lambda: open({str(tmp_path / "marker")!r}, "w").write("x"))
        attempt("write_usr", lambda: open("/usr/dv2s-marker", "w").write("x"))
        attempt("write_root", lambda: open("/dv2s-marker", "w").write("x"))
        attempt("write_dev", lambda: open("/dev/dv2s-marker", "w").write("x"))  # /dev is a tmpfs of no set size
        attempt("shm_over_1mib", lambda: open("/dev/shm/big", "wb").write(b"x" * (2 << 20)))
        attempt("memfd", lambda: os.memfd_create("big"))  # memory the address-space limit does not count
        attempt("unshare", lambda: os.unshare(os.CLONE_NEWUSER) if hasattr(os, "unshare") else (_ for _ in ()).throw(OSError()))
        libc = ctypes.CDLL(None, use_errno=True)
        out["ptrace"] = "refused" if libc.ptrace(16, 1, 0, 0) != 0 else "allowed"  # PTRACE_ATTACH to pid 1
        out["kill_outside"] = "refused" if libc.kill({os.getpid()}, 0) != 0 else "allowed"  # this test's process
        open("/dev/null", "w").write("device nodes still work")
        with open("/tmp/ok", "w") as f:
            f.write("scratch works")
        out["scratch"] = open("/tmp/ok").read()
        print(json.dumps(out))
    """, tmp_path)
    refused = {k: v for k, v in result.items() if k != "scratch"}
    assert {k for k, v in refused.items() if v != "refused"} == set(), result
    assert result["scratch"] == "scratch works"
    assert not (tmp_path / "marker").exists()


def _session_processes(sid: int):
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            if os.getsid(int(pid)) == sid:
                found.append(int(pid))
        except OSError:
            pass
    return found


def test_killing_a_worker_leaves_no_process():
    worker = JailedProcess("envs.jail_worker", name="probe")
    pid = worker.pid
    assert _session_processes(pid)
    worker.kill()
    for _ in range(50):
        if not _session_processes(pid):
            break
        time.sleep(0.1)
    assert _session_processes(pid) == []


def test_wire_refuses_what_is_not_data():
    import pickle

    header, buffers = wire.encode({"obs": np.zeros((2, 3), np.float32), "n": 1, "s": "x", "l": [1.5, None]})
    value = wire.decode(header, buffers)
    assert value["obs"].shape == (2, 3) and value["l"] == [1.5, None]
    with pytest.raises(JailProtocolError):
        wire.decode(pickle.dumps({"a": 1}), [])
    with pytest.raises(JailProtocolError):  # object arrays would unpickle
        wire.decode(json.dumps({"__nd__": 0, "dtype": "|O", "shape": [1]}).encode(), [b"\0" * 8])
    with pytest.raises(JailProtocolError):  # the buffer does not hold what the shape says
        wire.decode(json.dumps({"__nd__": 0, "dtype": "<f8", "shape": [10**6]}).encode(), [b"\0" * 8])
    with pytest.raises(JailProtocolError):
        wire.decode(b"[" * 200000 + b"]" * 200000, [])
    with pytest.raises(JailProtocolError):
        wire.encode({"f": lambda: 0})


def test_a_worker_claiming_a_huge_message_is_refused_before_reading():
    read, write = os.pipe()
    os.write(write, struct.pack("<4sII", b"DV2S", 2**31, 1) + struct.pack("<Q", 2**40))
    os.close(write)
    with os.fdopen(read, "rb") as stream, pytest.raises(JailProtocolError, match="over the"):
        wire.read_message(stream, 2**20)


def test_a_header_of_many_small_objects_is_refused_before_parsing():
    # 40 MiB of "[]," would become ~700 MB of Python lists: refused by its declared size
    size = 40 * 2**20
    read, write = os.pipe()
    os.write(write, struct.pack("<4sII", b"DV2S", size, 0))
    os.close(write)
    with os.fdopen(read, "rb") as stream, pytest.raises(JailProtocolError, match=r"header of \d+ bytes is over .*bulk data"):
        wire.read_message(stream, 256 * 2**20)


LOOPING = textwrap.dedent("""
    param map = 'highway_straight'
    model scenic.domains.driving.model
    behavior Spin():
        take SetThrottleAction(0.1)
        x = 0
        while True:
            x = x + 1
    ego = new Car with behavior Spin()
""")


def test_a_script_that_never_yields_is_stopped_by_the_wall_clock(monkeypatch):
    from envs.dv2s_env import DV2SEnv
    from envs.errors import StepTimeoutError

    env = DV2SEnv(scenario=LOOPING, config={"step_time_limit": 1.0, "ego_policy": "scenic"},
                  jail_limits=JailLimits(request_seconds=8.0))
    pid = env.worker_pid
    with pytest.raises((StepTimeoutError, Exception)) as caught:
        env.reset(seed=0)
        env.step(1)
    assert "limit" in str(caught.value)
    env.close()
    assert _session_processes(pid) == []


def test_untrusted_text_runs_in_the_jail_shipped_names_in_process():
    from envs.dv2s_env import DV2SEnv
    from envs.jailed_env import JailedDV2SEnv

    text = (bwrap.CODE_ROOT / "scenario_bank" / "scenarios" / SHIPPED / "scenario.scenic").read_text()
    assert type(DV2SEnv(scenario=SHIPPED)).__name__ == "DV2SEnv"
    assert type(DV2SEnv(scenario=text)).__name__ == "DV2SEnv"  # the shipped text, by hash
    edited = DV2SEnv(scenario=text + "\n# edited\n")
    assert isinstance(edited, JailedDV2SEnv)
    edited.close()


def test_an_in_process_env_does_not_switch_to_a_script_outside_its_own(tmp_path):
    """A bank folder whose scripts are not shipped: an env made from a shipped name in it runs in
    process, and ``reset(options={"scenario": ...})`` may not reach the edited neighbour there."""
    import shutil

    from envs.dv2s_env import DV2SEnv

    bank = tmp_path / "bank"
    for name in (SHIPPED, "edited"):
        shutil.copytree(bwrap.CODE_ROOT / "scenario_bank" / "scenarios" / SHIPPED, bank / name)
    marker = tmp_path / "ran"
    with open(bank / "edited" / "scenario.scenic", "a", encoding="utf-8") as handle:
        handle.write(f"\nsimulation().env.spec.make  # {marker}\n")
    env = DV2SEnv(scenario=SHIPPED, bank_dir=str(bank), config={"duration": 1.0})
    assert not env.runs_in_jail
    with pytest.raises(ValueError, match="needs its own env"):
        env.reset(seed=0, options={"scenario": "edited"})
    env.reset(seed=0, options={"scenario": SHIPPED})
    env.close()
    assert not marker.exists()


def test_map_files_go_into_the_jail_once_each_and_within_a_total(tmp_path):
    """However often and however spelt a script names its map, its bytes are read and sent once;
    more map files than a scenario uses are refused before they are read."""
    from envs.dv2s_env import ScenarioRef
    from envs.jailed_env import MAX_MAP_FILES, JailedDV2SEnv

    (tmp_path / "road.xodr").write_bytes(b"<OpenDRIVE/>")
    spellings = ["road.xodr", "./road.xodr", "././road.xodr", ".//road.xodr"]
    text = '"""\n' + "".join(f"param map = localPath('{s}')\n" for s in spellings) + '"""\n'
    script = tmp_path / "s.scenic"
    payload = JailedDV2SEnv._scenario_payload(ScenarioRef(name="s", path=str(script)), text)
    assert list(payload["files"]) == ["road.xodr"]
    for k in range(MAX_MAP_FILES + 1):
        (tmp_path / f"m{k}.xodr").write_bytes(b"<OpenDRIVE/>")
    many = "".join(f"param map = 'm{k}.xodr'\n" for k in range(MAX_MAP_FILES + 1))
    with pytest.raises(ValueError, match="more than .* map files"):
        JailedDV2SEnv._scenario_payload(ScenarioRef(name="s", path=str(script)), many)
    (tmp_path / "sub").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "private.xodr").write_bytes(b"secret")
    from scenario_bank.safe_files import UnsafeInputError

    with pytest.raises(UnsafeInputError):
        JailedDV2SEnv._scenario_payload(ScenarioRef(name="s", path=str(script)), "param map = 'sub/private.xodr'\n")


def test_compile_scenario_refuses_untrusted_text_outside_the_jail():
    from envs.errors import UntrustedScenarioError
    from envs.scenarios import compile_scenario

    with pytest.raises(UntrustedScenarioError, match="jail"):
        compile_scenario("param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n")


def test_jailed_env_matches_the_in_process_env_step_for_step():
    """Same scene, same actions: the jailed client and the trusted in-process env agree exactly."""
    from envs.dv2s_env import DV2SEnv
    from policies.evaluation import trajectory_hash
    from policies.rule_based import CautiousDriver

    text = (bwrap.CODE_ROOT / "scenario_bank" / "scenarios" / SHIPPED / "scenario.scenic").read_text()
    hashes, observations = [], []
    for env in (DV2SEnv(scenario=text, jail=True), DV2SEnv(scenario=text, trusted=True)):
        driver = CautiousDriver(env)
        obs, info = env.reset(seed=11)
        seen = [obs]
        for _ in range(30):
            obs, reward, terminated, truncated, info = env.step(driver.act())
            seen.append(obs)
            if terminated or truncated:
                break
        hashes.append(trajectory_hash(env.unwrapped.trace))
        observations.append(np.stack(seen))
        env.close()
    assert hashes[0] == hashes[1]
    np.testing.assert_array_equal(observations[0], observations[1])


def test_jailed_env_passes_gymnasiums_checker_and_renders():
    from gymnasium.utils.env_checker import check_env

    import dv2s_gym  # noqa: F401
    text = (bwrap.CODE_ROOT / "scenario_bank" / "scenarios" / SHIPPED / "scenario.scenic").read_text() + "\n#\n"
    env = gym.make("DV2S-v0", scenario=text, render_mode="rgb_array", config={"duration": 2.0})
    check_env(env.unwrapped, skip_render_check=True)
    env.reset(seed=1)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.std() > 0
    env.close()


def test_the_shipped_manifest_lists_exactly_the_shipped_scripts():
    from scenario_bank.shipped import MANIFEST, manifest_text

    assert MANIFEST.read_text(encoding="ascii") == manifest_text(), "run python -m scenario_bank.shipped"
