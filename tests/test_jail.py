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

from process_tree import descendants

from scenario_bank.jail import JailedProcess, JailError, JailLimitError, JailLimits, JailProtocolError, jail_status
from scenario_bank.jail import bwrap, seccomp, wire, zygote
from scenario_bank.jail.limits import START_CPU_SECONDS
from scenario_bank.jail.process import discard_spares

pytestmark = pytest.mark.skipif(not jail_status()[0], reason=f"no jail here: {jail_status()[1]}")

CANARY = "sk-dv2s-canary-0123456789"
SHIPPED = "highway_cut_in_from_left"
PROBE = "scenario_bank.jail.probe"  # a worker that runs the Python it is sent


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


def _running(pid) -> bool:
    """Whether process ``pid`` exists on this machine and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _eventually(condition, seconds: float = 10.0) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


@pytest.fixture(params=[True, False], ids=["zygote", "bubblewrap"])
def forked(request, monkeypatch):
    """Run the test with workers forked by the zygote, then with a bubblewrap per worker."""
    if request.param:
        if not zygote.zygote_status()[0]:
            pytest.skip(f"no zygote here: {zygote.zygote_status()[1]}")
    else:
        monkeypatch.setenv("DV2S_JAIL_ZYGOTE", "0")
    return request.param


@pytest.fixture
def zygote_only():
    if not zygote.zygote_status()[0]:
        pytest.skip(f"no zygote here: {zygote.zygote_status()[1]}")


def _run(worker: JailedProcess, code: str):
    return worker.call("run", code=textwrap.dedent(code))


def test_killing_a_worker_leaves_no_process(forked):
    worker = JailedProcess("envs.jail_worker", name="probe")
    assert worker.forked == forked
    pid = worker.pid
    assert _running(pid)
    worker.kill()
    assert _eventually(lambda: not _running(pid) and not _session_processes(pid))


def test_stopping_the_zygotes_leaves_no_process(zygote_only):
    workers = [JailedProcess(PROBE, name="probe") for _ in range(2)]
    fork_server = zygote._ZYGOTES[(os.getpid(), PROBE)]
    jail = descendants(fork_server.pid)  # bubblewrap's init, the zygote, two middle processes, two workers
    assert len(jail) >= 6 and {w.pid for w in workers} <= set(jail)
    discard_spares()
    assert _eventually(lambda: not any(_running(pid) for pid in [fork_server.pid, *jail]))
    for worker in workers:
        with pytest.raises(JailError):
            _run(worker, "result = 1")


def test_the_zygote_and_its_workers_die_with_the_users_process(zygote_only, tmp_path):
    code = (f"import os, sys, time; sys.path.insert(0, {str(bwrap.CODE_ROOT)!r})\n"
            "from scenario_bank.jail import JailedProcess, zygote\n"
            f"worker = JailedProcess({PROBE!r})\n"
            f"print(worker.pid, zygote._ZYGOTES[(os.getpid(), {PROBE!r})].pid, flush=True)\n"
            "time.sleep(600)\n")
    user = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        worker_pid, zygote_pid = map(int, user.stdout.readline().split())
        assert _running(worker_pid) and _running(zygote_pid)
    finally:
        user.kill()
        user.wait()
    assert _eventually(lambda: not _running(worker_pid) and not _running(zygote_pid))


def test_a_forked_worker_sees_and_reaches_only_itself(zygote_only):
    first, second = JailedProcess(PROBE, name="first"), JailedProcess(PROBE, name="second")
    try:
        assert first.forked and second.forked
        _run(second, """
            import socket
            open("/tmp/work/secret", "w").write("the sibling")
            listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            listener.bind("\\0dv2s-sibling")  # abstract names belong to the network namespace
            listener.listen()
            import sys
            sys.dv2s_listener = listener  # kept open after this request
            socket.socket(socket.AF_UNIX, socket.SOCK_STREAM).connect("\\0dv2s-sibling")
            result = None
        """)
        seen = _run(first, """
            import os
            reached = []
            for pid in range(2, 4097):  # 1 is itself
                try:
                    os.kill(pid, 0)
                    reached.append(pid)
                except ProcessLookupError:
                    pass
            import socket
            try:
                socket.socket(socket.AF_UNIX, socket.SOCK_STREAM).connect("\\0dv2s-sibling")
                reached.append("the sibling's socket")
            except ConnectionRefusedError:
                pass
            result = {"ids": [os.getpid(), os.getpgid(0), os.getsid(0)], "reached": reached,
                      "processes": sorted(int(p) for p in os.listdir("/proc") if p.isdigit()),
                      "scratch": sorted(os.listdir("/tmp")), "secret": os.path.exists("/tmp/work/secret")}
        """)
        assert seen == {"ids": [1, 1, 1], "reached": [], "processes": [1], "scratch": ["home", "tmp", "work"],
                        "secret": False}
        everyone = _run(first, """
            import os, signal
            try:
                os.kill(-1, signal.SIGKILL)  # every process it may signal but itself
                result = "killed some"
            except ProcessLookupError:
                result = "no one"
        """)
        assert everyone == "no one"
        # its process group is itself alone, and the init of a PID namespace ignores its own SIGKILL
        assert _run(first, "import os, signal; os.killpg(0, signal.SIGKILL); result = 'here'") == "here"
        assert _run(second, "result = open('/tmp/work/secret').read()") == "the sibling"
        with JailedProcess(PROBE, name="third") as third:  # the zygote is alive too
            assert third.forked and _run(third, "import os; result = os.listdir('/tmp/work')") == []
    finally:
        first.close()
        second.close()


def test_killing_one_forked_worker_leaves_the_zygote_and_its_siblings(zygote_only):
    first, second = JailedProcess(PROBE, name="first"), JailedProcess(PROBE, name="second")
    fork_server = zygote._ZYGOTES[(os.getpid(), PROBE)]
    pid = first.pid
    first.kill()
    assert _eventually(lambda: not _running(pid))
    assert _running(second.pid) and _run(second, "result = 2 + 2") == 4
    with JailedProcess(PROBE, name="third") as third:
        assert _run(third, "result = 'new'") == "new"
    assert zygote._ZYGOTES[(os.getpid(), PROBE)] is fork_server and fork_server.alive()
    second.close()


def test_the_user_process_refuses_a_huge_header_and_shows_no_escape_sequences():
    """Code running in a worker writes its own bytes to the reply pipe: a header too large to parse is
    refused by its declared size, and an error text full of terminal escapes arrives harmless."""
    from scenario_bank.jail.process import JailRemoteError

    with JailedProcess(PROBE, name="probe") as worker:
        with pytest.raises(JailRemoteError) as caught:
            _run(worker, "raise RuntimeError(chr(27) + ']0;TITLE' + chr(7) + chr(27) + '[2J cleared')")
        assert "\x1b" not in str(caught.value) and "\x07" not in str(caught.value) and "cleared" in str(caught.value)
    with JailedProcess(PROBE, name="probe") as worker:
        with pytest.raises(JailProtocolError, match="header of .* over"):
            _run(worker, "import os, struct\n"
                         "os.write(outbound_fd, struct.pack('<4sII', b'DV2S', 64 * 2**20, 0) + b'[' * 4096)\n"
                         "import time; time.sleep(30)")


def test_where_no_zygote_can_start_each_worker_gets_a_bubblewrap(zygote_only, monkeypatch):
    monkeypatch.setattr(zygote, "_PROBE", {})
    monkeypatch.setattr(zygote, "_ZYGOTES", {})
    monkeypatch.setattr(zygote, "CAPABILITIES", ())  # so it cannot mount the procfs its workers need
    with JailedProcess(PROBE, name="probe") as worker:
        assert not worker.forked and _run(worker, "result = 1") == 1
    ok, why = zygote.zygote_status()
    assert not ok and "Operation not permitted" in why and not zygote.enabled()


REFUSALS = """
    import ctypes, errno, json, os, socket
    out = {}
    def attempt(name, call):
        try:
            call()
            out[name] = "allowed"
        except OSError as error:
            out[name] = "refused"
    libc = ctypes.CDLL(None, use_errno=True)
    def libc_call(name, *args):
        if getattr(libc, name)(*args) != 0:
            raise OSError(ctypes.get_errno(), name)
    attempt("fork", os.fork)
    attempt("inet", lambda: socket.socket(socket.AF_INET, socket.SOCK_STREAM))
    attempt("inet6", lambda: socket.socket(socket.AF_INET6, socket.SOCK_DGRAM))
    attempt("ptrace", lambda: libc_call("ptrace", 16, 1, 0, 0))  # PTRACE_ATTACH
    attempt("unshare", lambda: libc_call("unshare", 0x10000000))  # CLONE_NEWUSER
    attempt("mount", lambda: libc_call("mount", b"none", b"/tmp/tmp", b"tmpfs", 0, None))
    attempt("memfd", lambda: os.memfd_create("big"))
    attempt("kill_outside", lambda: os.kill(HOST_PID, 0))
    attempt("write_usr", lambda: open("/usr/dv2s-marker", "w").write("x"))
    attempt("write_dev", lambda: open("/dev/dv2s-marker", "w").write("x"))
    def write(path, size):
        with open(path, "wb") as handle:  # closing flushes: a short write fails there
            handle.write(b"x" * size)
    attempt("shm_over_1mib", lambda: write("/dev/shm/big", 2 << 20))
    attempt("file_over_limit", lambda: write("/tmp/tmp/file", FILE_BYTES + 1))
    attempt("scratch_over_limit", lambda: [write(f"/tmp/tmp/part{i}", FILE_BYTES) for i in range(8)])
    status = dict(line.split(":", 1) for line in open("/proc/self/status"))
    import resource
    result = {"attempts": out, "env": dict(os.environ), "uid": os.getuid(),
              "status": {k: status[k].strip() for k in ("CapInh", "CapPrm", "CapEff", "CapBnd", "CapAmb",
                                                        "NoNewPrivs", "Seccomp")},
              "rlimits": {name: list(resource.getrlimit(getattr(resource, name)))
                          for name in ("RLIMIT_AS", "RLIMIT_CPU", "RLIMIT_FSIZE", "RLIMIT_NOFILE", "RLIMIT_CORE")}}
"""


def test_a_worker_is_refused_and_holds_what_a_jailed_worker_does(forked, monkeypatch):
    monkeypatch.setenv("CANARY_API_KEY", CANARY)
    limits = JailLimits(cpu_seconds=50, memory_bytes=3 * 2**30, file_bytes=2 * 2**20, scratch_bytes=8 * 2**20,
                        open_files=100)
    with JailedProcess(PROBE, name="probe", limits=limits) as worker:
        assert worker.forked == forked
        found = _run(worker, REFUSALS.replace("HOST_PID", str(os.getpid())).replace("FILE_BYTES", str(2 * 2**20)))
    assert {k for k, v in found["attempts"].items() if v != "refused"} == set(), found["attempts"]
    assert CANARY not in json.dumps(found["env"]) and set(found["env"]) <= set(bwrap.worker_environment()) | {"PWD"}
    assert found["uid"] == 65534
    assert found["status"] == {"CapInh": "0000000000000000", "CapPrm": "0000000000000000",
                               "CapEff": "0000000000000000", "CapBnd": "0000000000000000",
                               "CapAmb": "0000000000000000", "NoNewPrivs": "1", "Seccomp": "2"}
    rlimits = found["rlimits"]
    assert rlimits["RLIMIT_AS"] == [3 * 2**30] * 2 and rlimits["RLIMIT_FSIZE"] == [2 * 2**20] * 2
    assert rlimits["RLIMIT_NOFILE"] == [100, 100] and rlimits["RLIMIT_CORE"] == [0, 0]
    cpu = 50 if forked else 50 + START_CPU_SECONDS  # a forked worker's CPU time starts at zero, with the budget
    assert rlimits["RLIMIT_CPU"] == [cpu, cpu + 2]


KERNEL_SETTINGS = """
    import errno, os
    found = {}
    for path in ("/proc/sys/vm/swappiness", "/proc/sys/kernel/core_pattern", "/proc/sysrq-trigger",
                 "/proc/irq/default_smp_affinity"):
        try:
            fd = os.open(path, os.O_WRONLY)  # opened only: nothing is written, whatever happens
        except OSError as error:
            found[path] = errno.errorcode.get(error.errno, str(error.errno))
        else:
            os.close(fd)
            found[path] = "opened"
    result = found
"""


def test_a_worker_cannot_open_kernel_settings_for_writing(forked):
    with JailedProcess(PROBE, name="probe") as worker:
        assert worker.forked == forked
        found = _run(worker, KERNEL_SETTINGS)
    assert found["/proc/sys/vm/swappiness"] in ("EROFS", "EACCES", "EPERM"), found
    assert {path: how for path, how in found.items() if how == "opened"} == {}, found


THREADS = """
    import threading
    release = threading.Event()
    started = []
    try:
        for _ in range(400):
            thread = threading.Thread(target=release.wait, daemon=True)
            thread.start()
            started.append(thread)
    except RuntimeError:  # can't start new thread: the limit
        pass
    release.set()
    for thread in started:
        thread.join()
    result = len(started)
"""


def test_a_worker_cannot_start_more_threads_than_its_process_limit(forked):
    import os

    from scenario_bank.jail.pids_cgroup import pids_cgroup_folder

    if os.geteuid() == 0 and pids_cgroup_folder() is None:
        pytest.skip("run as root with no writable pids cgroup: the kernel does not apply RLIMIT_NPROC to root, "
                    "so nothing here can hold the thread limit")
    limits = JailLimits(processes=32)
    with JailedProcess(PROBE, name="probe", limits=limits) as worker:
        assert worker.forked == forked
        started = _run(worker, THREADS)
    assert started < 32, started  # the main thread counts too


@pytest.mark.slow
def test_a_busy_forked_worker_is_stopped_by_the_wall_clock_and_the_cpu_limit(zygote_only):
    with JailedProcess(PROBE, name="spinner", limits=JailLimits(request_seconds=2)) as worker:
        pid = worker.pid
        with pytest.raises(JailLimitError, match="2 s wall-clock limit") as caught:
            _run(worker, "while True: pass")
        assert caught.value.limit == "wall" and _eventually(lambda: not _running(pid))
    with JailedProcess(PROBE, name="spinner", limits=JailLimits(cpu_seconds=1, request_seconds=120)) as worker:
        with pytest.raises(JailLimitError, match="1 s CPU-time limit") as caught:
            _run(worker, "while True: pass")
        assert caught.value.limit == "cpu"


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
    # 10 MiB of "[]," would become ~190 MB of Python lists: refused by its declared size
    size = 10 * 2**20
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


@pytest.mark.slow
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
    assert _eventually(lambda: not _running(pid) and _session_processes(pid) == [])


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
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


def test_every_shipped_sidecar_hash_is_its_script(tmp_path, monkeypatch):
    import shutil

    from scenario_bank import shipped

    assert shipped.stale_sidecars() == [], "run python -m scenario_bank.shipped"
    # On a copy: an edited script makes its sidecar stale, and the refresh mends that field only.
    copy = tmp_path / "scenarios"
    shutil.copytree(shipped._SCENARIOS / SHIPPED, copy / SHIPPED)
    monkeypatch.setattr(shipped, "_SCENARIOS", copy)
    script = copy / SHIPPED / "scenario.scenic"
    sidecar = copy / SHIPPED / "meta.json"
    before = json.loads(sidecar.read_text())
    script.write_text(script.read_text() + "# edited\n")
    assert shipped.stale_sidecars() == [sidecar]
    assert shipped.refresh_sidecars() == [sidecar]
    after = json.loads(sidecar.read_text())
    assert after.pop("content_hash") == shipped.text_digest(script.read_text())
    before.pop("content_hash")
    assert after == before and shipped.stale_sidecars() == []


@pytest.mark.slow
def test_compiling_a_shipped_scenario_imports_nothing_from_the_current_folder(tmp_path):
    # Scenic puts the current folder first on sys.path while it compiles, and its driving domain
    # imports `attr` and `shapely` on first use; planted copies there must never run.
    folder = tmp_path / "cwd"
    folder.mkdir()
    for module in ("attr", "shapely", "numpy", "dv2s_planted"):
        marker = tmp_path / f"{module}.imported"
        (folder / f"{module}.py").write_text(f"open({str(marker)!r}, 'w').write('imported')\n")
    code = textwrap.dedent(f"""
        import sys
        from envs.scenarios import compile_scenario, read_scenario_file
        path = {str(bwrap.CODE_ROOT / "scenario_bank" / "scenarios" / SHIPPED / "scenario.scenic")!r}
        compile_scenario(read_scenario_file(path), name="shipped")
        print("compiled")
    """)
    env = dict(os.environ, PYTHONPATH=str(bwrap.CODE_ROOT))
    # -P: the interpreter itself puts no current folder on sys.path, as with the `dv2s` command
    done = subprocess.run([sys.executable, "-P", "-c", code], cwd=folder, env=env, capture_output=True,
                          timeout=300)
    assert done.returncode == 0 and b"compiled" in done.stdout, done.stderr.decode()[-2000:]
    assert sorted(p.name for p in tmp_path.glob("*.imported")) == []


def test_the_compile_limit_follows_its_own_variable_else_the_request_limit(monkeypatch):
    monkeypatch.delenv("DV2S_JAIL_COMPILE_SECONDS", raising=False)
    monkeypatch.delenv("DV2S_JAIL_REQUEST_SECONDS", raising=False)
    assert JailLimits.from_env().compile_seconds == 300.0
    monkeypatch.setenv("DV2S_JAIL_REQUEST_SECONDS", "7")
    assert JailLimits.from_env().compile_seconds == 7.0
    monkeypatch.setenv("DV2S_JAIL_COMPILE_SECONDS", "12")
    limits = JailLimits.from_env()
    assert (limits.request_seconds, limits.compile_seconds) == (7.0, 12.0)
