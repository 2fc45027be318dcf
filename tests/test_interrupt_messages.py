"""What `dv2s` prints on Ctrl-C: a line of its own after any progress bar, and what was really kept."""

from __future__ import annotations

import argparse
import sys

import pytest
from tqdm import tqdm

from dv2s_gym.cli.interrupts import episodes_kept_note, report_interrupted


def test_the_interrupted_line_starts_a_line_of_its_own_after_an_open_bar(capsys):
    bar = tqdm(total=10, file=sys.stderr, desc="mining", mininterval=0)
    bar.update(3)
    code = report_interrupted(argparse.Namespace(command="mine"), "a note")
    err = capsys.readouterr().err
    assert code == 130
    lines = err.replace("\r", "\n").split("\n")
    assert "dv2s: interrupted; a note" in lines
    assert not err.rstrip("\n").endswith("it/s]") and err.rstrip("\n").endswith("dv2s: interrupted; a note")
    assert bar.disable or bar not in getattr(tqdm, "_instances", ())  # closed: not redrawn at exit


def test_an_interrupted_run_says_what_it_kept(tmp_path):
    missing = episodes_kept_note(tmp_path / "out" / "episodes.jsonl")
    assert "no episode had finished, so nothing was kept" in missing and "kept in" not in missing
    (tmp_path / "episodes.jsonl").write_text('{"index": 0}\n{"index": 1}\n')
    note = episodes_kept_note(tmp_path / "episodes.jsonl")
    assert note.startswith(f"2 finished episodes are kept in {tmp_path / 'episodes.jsonl'}") and "resume" in note


def test_ctrl_c_of_mine_before_its_first_episode_does_not_claim_a_missing_file(tmp_path, capsys, monkeypatch):
    import dv2s_gym.mining.miner as miner
    from cli_helpers import run

    def interrupted(*args, **options):
        raise KeyboardInterrupt

    monkeypatch.setattr(miner, "mine", interrupted)
    code, _, err = run(capsys, "mine", "--policy", "rule", "--budget", "4", "--no-progress", "--no-convert",
                       "--out", tmp_path / "mine")
    assert code == 130 and "nothing was kept" in err and "episodes.jsonl" not in err


_SLOW_TEARDOWN = r'''
import atexit, multiprocessing, sys, time
from pathlib import Path

class SlowToCollect:  # stands for a run's big objects, slow to collect at the interpreter's teardown
    def __del__(self):
        time.sleep(60)

def interrupted(*args, **options):
    raise KeyboardInterrupt

if __name__ == "__main__":
    import dv2s_gym.mining.miner as miner
    from dv2s_gym.cli import main

    marker = Path(sys.argv[1])
    atexit.register(marker.write_text, "exit handlers ran")
    child = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(120,), daemon=True)
    child.start()
    Path(sys.argv[2]).write_text(str(child.pid))
    held = SlowToCollect()
    miner.mine = interrupted
    sys.argv = ["dv2s", "mine", "--policy", "rule", "--no-convert", "--no-progress", "--out", sys.argv[3]]
    sys.exit(main())
'''


def test_an_interrupted_command_exits_at_once_with_its_exit_handlers_run_and_no_child_left(tmp_path):
    import os
    import subprocess
    import time

    script = tmp_path / "slow_teardown.py"
    script.write_text(_SLOW_TEARDOWN)
    marker, child_pid = tmp_path / "atexit.txt", tmp_path / "child.pid"
    began = time.monotonic()
    done = subprocess.run([sys.executable, str(script), str(marker), str(child_pid), str(tmp_path / "mine")],
                          capture_output=True, text=True, timeout=120, env=dict(os.environ, OMP_NUM_THREADS="1"))
    took = time.monotonic() - began
    assert done.returncode == 130 and "dv2s: interrupted" in done.stderr, done.stderr
    assert took < 40, f"{took:.0f} s: the interpreter's teardown ran"  # the object alone takes 60 s to collect
    assert marker.read_text() == "exit handlers ran"
    pid = int(child_pid.read_text())
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and _alive(pid):
        time.sleep(0.1)
    assert not _alive(pid), "a worker process was left behind"


def _alive(pid: int) -> bool:
    from pathlib import Path

    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.slow
def test_training_envs_cut_off_mid_step_by_ctrl_c_close_without_hanging():
    """Ctrl-C between two workers' answers: closing must not wait for an answer the first worker already gave."""
    import threading

    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from policies.training import close_vec_env

    venv = SubprocVecEnv([lambda: gym.make("CartPole-v1")] * 2)
    venv.reset()
    processes = list(venv.processes)
    venv.step_async(np.zeros(2, dtype=int))
    venv.remotes[0].recv()  # step_wait had read the first answer when Ctrl-C came

    def interrupted_run():
        try:
            raise KeyboardInterrupt
        finally:
            close_vec_env(venv)

    def run():
        try:
            interrupted_run()
        except KeyboardInterrupt:
            pass

    closing = threading.Thread(target=run, daemon=True)
    closing.start()
    closing.join(30)
    assert not closing.is_alive(), "closing the envs hangs"
    assert venv.closed and not any(p.is_alive() for p in processes)
