"""``--backend ray``: the test starts a local Ray head (``ray start --head --block`` in its own
process group, loopback only, 2 CPUs, no dashboard), the backend connects to it by address, the
episodes equal the local backend's (same trajectory hashes), traces come back to the driver, a
crashed or hung actor is retried once then reported, and an address where nothing listens fails
at once with the fix. The head is stopped by terminating the `ray start` process this module
started (not `ray stop`, which would stop every Ray instance on the machine)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

import ray  # the ray extra (scripts/setup.sh installs it): pip install -e '.[ray]'

from dv2s_gym.regress.tasks import KIND
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.ray_pool import RayBackend, RayUnavailableError

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ["highway_cut_in_from_left", "urban_pedestrian_crossing"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ray_executable() -> str:
    found = Path(sys.executable).with_name("ray")
    return str(found) if found.exists() else shutil.which("ray") or "ray"


@contextlib.contextmanager
def _ray_head(**head_env: str):
    """A Ray head on 127.0.0.1 (``head_env`` added to its environment); stopped (its process group killed) at the
    end. Its HOME, and this process's, is a clean folder: a token a local Ray instance left in ~/.ray/auth_token
    would turn token authentication on."""
    port = _free_port()
    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    home = pytest.MonkeyPatch()
    home.setenv("HOME", temp)
    env = dict(os.environ, RAY_DISABLE_USAGE_STATS="1", OMP_NUM_THREADS="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]),
               **head_env)
    command = [_ray_executable(), "start", "--head", "--block", "--node-ip-address=127.0.0.1", f"--port={port}",
               "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats",
               "--object-store-memory=100000000", f"--temp-dir={temp}",
               f"--ray-client-server-port={_free_port()}", f"--dashboard-agent-listen-port={_free_port()}",
               f"--dashboard-agent-grpc-port={_free_port()}", f"--metrics-export-port={_free_port()}",
               f"--runtime-env-agent-port={_free_port()}"]
    head = subprocess.Popen(command, env=env, cwd=temp, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    address = f"127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if head.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"ray start failed: {head.stderr.read().decode()[-2000:]}")
                time.sleep(0.5)
        yield address
    finally:
        if ray.is_initialized():
            ray.shutdown()
        head.terminate()  # `ray start --block` drains and stops the processes it started
        try:
            head.wait(60)
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(head.pid, signal.SIGKILL)  # anything of this cluster still there (its own process group)
        except ProcessLookupError:
            pass
        head.wait(10)
        home.undo()
        shutil.rmtree(temp, ignore_errors=True)


@pytest.fixture(scope="module")
def ray_address():
    """A Ray head on 127.0.0.1 for this module."""
    with _ray_head() as address:
        yield address


def _task(policy: str, scenario: str, seed: int, trace_dir=None, role: str = "candidate") -> dict:
    return {"kind": KIND, "policy": policy, "role": role, "scenario": scenario, "seed": seed, "env_config": {"duration": 8},
            "bank_dir": None, "trace_dir": None if trace_dir is None else str(trace_dir)}


def test_an_address_where_nothing_listens_fails_at_once_with_the_fix():
    port = _free_port()
    started = time.monotonic()
    with pytest.raises(RayUnavailableError) as error:
        RayBackend(address=f"127.0.0.1:{port}", connect_timeout=2)
    message = str(error.value)
    assert f"127.0.0.1:{port}" in message and "ray start --head" in message
    assert "\n" not in message
    assert isinstance(error.value, WorkerError)
    assert time.monotonic() - started < 60  # not Ray's own minutes of retrying
    with pytest.raises(RayUnavailableError, match="is not HOST:PORT"):
        RayBackend(address="no-port-here")


@pytest.mark.slow
def test_a_crashed_or_hung_actor_is_retried_once_then_reported(ray_address):
    """An actor that dies (os._exit on the first action) or hangs (no result within the timeout) is
    replaced and its task run once more; the second failure becomes an error result, and the backend
    goes on with the next task."""
    got = []
    with RayBackend(address=ray_address, workers=1, timeout=300) as backend:
        backend.run([_task("regress_misbehaving_policies:crash", SCENARIOS[0], 0)], got.append)
        backend.timeout = 4
        backend.run([_task("regress_misbehaving_policies:hang?at=load", SCENARIOS[0], 1)], got.append)
    crashed, hung = got
    assert crashed["id"] == f"{SCENARIOS[0]}/0" and hung["id"] == f"{SCENARIOS[0]}/1"
    assert "died" in crashed["error"] and "2 attempts" in crashed["error"], crashed
    assert "hung (no result after 4 s)" in hung["error"] and "2 attempts" in hung["error"], hung
    assert crashed["role"] == hung["role"] == "candidate"


@pytest.mark.slow
def test_the_command_names_an_unreachable_address_and_how_to_start_a_cluster(tmp_path):
    port = _free_port()
    out = subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "regress", "--policy", "rule", "--baseline", "idm",
                          "--scenario", SCENARIOS[0], "--episodes", "2", "--backend", "ray",
                          "--address", f"127.0.0.1:{port}", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=300, cwd=ROOT,
                         env=dict(os.environ, PYTHONPATH=str(ROOT), RAY_DISABLE_USAGE_STATS="1"))
    assert out.returncode == 2, out.stderr
    last = out.stderr.strip().splitlines()[-1]
    assert last.startswith("dv2s: error: Ray is not reachable at 127.0.0.1:") and "ray start --head" in last, out.stderr


@pytest.mark.slow
def test_run_regression_on_the_cluster_equals_the_local_run(ray_address, tmp_path):
    """`run_regression(..., backend="ray", address=...)`: the same episodes, verdicts and trajectory
    hashes as the local process pool."""
    from regress_call import run_regression

    common = dict(baseline="rule", scenarios=SCENARIOS, episodes=3, seed=0, env_config={"duration": 8},
                  workers=2, progress=False)
    on_ray = run_regression("rule?action_noise=0.5", backend="ray", address=ray_address,
                            out_dir=tmp_path / "ray", **common)
    local = run_regression("rule?action_noise=0.5", backend="local", out_dir=tmp_path / "local", **common)
    assert on_ray.to_dict()["settings"]["backend"] == "ray" and not on_ray.to_dict()["errors"]
    assert not ray.is_initialized()  # the backend disconnected when the run ended

    def hashes(report):
        return {(e["id"], role): e[role]["trajectory_hash"] for e in report.to_dict()["episodes"]
                for role in ("candidate", "baseline")}

    assert hashes(on_ray) == hashes(local) and len(hashes(local)) == 12
    assert on_ray.to_dict()["verdict"] == local.to_dict()["verdict"] and on_ray.to_dict()["newly_failing"] == local.to_dict()["newly_failing"]
    assert on_ray.to_dict()["scenarios"] == local.to_dict()["scenarios"]
    for episode in on_ray.to_dict()["episodes"]:  # traces of failed episodes came back into the run's folder
        trace = episode["candidate"]["trace"]
        assert bool(trace) == episode["candidate"]["failed"]
        if trace:
            assert (tmp_path / "ray" / trace).read_bytes() == (tmp_path / "local" / trace).read_bytes()
    assert on_ray.to_dict()["newly_failing"], "no failed episode: the trace transfer went untested"


@pytest.mark.slow
def test_mining_on_ray_equals_mining_locally(ray_address, tmp_path):
    """``dv2s mine --backend ray``: the same records as the local pool, failed episodes' traces shipped back."""
    from mining_helpers import mine

    common = dict(budget=8, sampler="cross-entropy", scenarios=["highway_lead_vehicle_brakes"], seed=5,
                  env_config={"duration": 5}, progress=False, reports=False, policy="keep_lane", batch=4)
    local = mine(out=tmp_path / "local", workers=2, **common)
    remote = mine(out=tmp_path / "ray", backend="ray", address=ray_address, workers=2, **common)
    key = lambda run: [(r.index, r.seed, r.params, r.result.trajectory_hash, r.avoidable)  # noqa: E731
                       for r in run.records]
    assert key(remote) == key(local)
    failed = [r for r in remote.records if r.failure]
    assert failed, "keep_lane runs into the braking lead car in some of these scenes"
    for record in failed:
        assert (tmp_path / "ray" / record.trace).is_file()


@pytest.mark.slow
def test_a_head_with_token_authentication_names_the_token_in_the_error(tmp_path):
    """A head started by a user with a ~/.ray/auth_token requires it; a process without it gets the one-line error
    naming the token and how to pass it, and passing it that way connects."""
    token = "0123456789abcdef" * 4
    connect = ("from dv2s_gym.workers.ray_pool import RayBackend\n"
               "import sys\n"
               "try:\n    RayBackend(address=sys.argv[1], workers=1)\n"
               "except Exception as error:\n    print(type(error).__name__, error)\nelse:\n    print('connected')\n")
    with _ray_head(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token) as address:
        client = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
        client.update(HOME=str(tmp_path), OMP_NUM_THREADS="1", RAY_DISABLE_USAGE_STATS="1")
        refused = subprocess.run([sys.executable, "-c", connect, address], env=client, capture_output=True,
                                 text=True, timeout=300)
        line = refused.stdout.strip().splitlines()[-1]
        assert line.startswith("RayUnavailableError cannot connect to Ray at " + address), refused.stdout
        assert "RAY_AUTH_MODE=token RAY_AUTH_TOKEN=" in line and "~/.ray/auth_token" in line
        allowed = subprocess.run([sys.executable, "-c", connect, address], timeout=300, capture_output=True, text=True,
                                 env=dict(client, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token))
        assert allowed.stdout.strip().splitlines()[-1] == "connected", allowed.stdout + allowed.stderr[-2000:]
