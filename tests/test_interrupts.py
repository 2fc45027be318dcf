"""Ctrl-C during a long `dv2s` step: one line saying what was kept and how to resume, exit 130, and no
process of the run left behind, whether the signal goes to the whole process group (a terminal's
Ctrl-C) or to the main process alone."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from process_tree import descendants

pytestmark = pytest.mark.slow

TRAIN = ["train", "--steps", "64", "--envs", "1", "--vec-env", "dummy", "--hp", "n_steps=32", "--hp", "batch_size=32",
         "--scenarios", "highway_lead_vehicle_brakes", "highway_cut_in_from_left", "--card-seeds", "30",
         "--eval-jobs", "2"]


def _wait_for(path: Path, text: str, proc: subprocess.Popen, limit: float = 600.0) -> None:
    began = time.monotonic()
    while time.monotonic() - began < limit:
        if path.is_file() and text in path.read_text(errors="replace"):
            return
        assert proc.poll() is None, path.read_text(errors="replace")
        time.sleep(0.5)
    raise AssertionError(f"{text!r} did not appear in {limit} s")


@pytest.mark.parametrize("target", ["group", "main"])
def test_ctrl_c_during_the_card_evaluation_keeps_the_model_and_says_how_to_resume(tmp_path, target):
    err = tmp_path / "err.txt"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    with open(err, "w") as stderr:
        proc = subprocess.Popen([sys.executable, "-m", "dv2s_gym.cli", *TRAIN, "--out", str(tmp_path / "run")],
                                stdout=subprocess.DEVNULL, stderr=stderr, env=env, start_new_session=True)
    try:
        _wait_for(err, "card evaluation:", proc)
        time.sleep(3)  # the evaluation's workers are running episodes
        workers = set(descendants(proc.pid))
        assert workers, "the evaluation runs in worker processes"
        if target == "group":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGINT)
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    lines = [line for line in err.read_text().replace("\r", "\n").splitlines() if line.startswith("dv2s:")]
    assert code == 130
    assert len(lines) == 1 and lines[0].startswith("dv2s: interrupted; ") and "--resume" in lines[0], lines
    last = err.read_text().replace("\r", "\n").strip().splitlines()[-1]
    assert last == lines[0], "the interrupted line is the last one: on a line of its own, no bar redrawn after it"
    card = json.loads((tmp_path / "run" / "model_card.json").read_text())
    assert (tmp_path / "run" / "model.zip").is_file() and card["evaluation"] is None
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(Path(f"/proc/{pid}").exists() for pid in workers):
        time.sleep(0.2)
    assert not [pid for pid in workers if Path(f"/proc/{pid}").exists()], "worker processes were left behind"


def test_ctrl_c_of_the_terminal_during_training_saves_a_checkpoint_at_the_step_reached(tmp_path):
    """The terminal's Ctrl-C reaches the env workers too: they leave it to the main process, which saves first."""
    err = tmp_path / "err.txt"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    argv = ["train", "--steps", "100000", "--envs", "2", "--hp", "n_steps=32", "--hp", "batch_size=32",
            "--scenarios", "highway_lead_vehicle_brakes", "--card-seeds", "0", "--checkpoint-freq", "0",
            "--eval-freq", "0", "--out", str(tmp_path / "run")]
    with open(err, "w") as stderr:
        proc = subprocess.Popen([sys.executable, "-m", "dv2s_gym.cli", *argv], stdout=subprocess.DEVNULL,
                                stderr=stderr, env=env, start_new_session=True)
    try:
        _wait_for(err, "step/s", proc)  # the bar moves: the workers are stepping
        workers = set(descendants(proc.pid))
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    line = err.read_text().replace("\r", "\n").strip().splitlines()[-1]
    assert code == 130
    assert line.startswith("dv2s: interrupted; training stopped at step ") and "--resume" in line, line
    checkpoint = Path(line.split("checkpoint ")[1].split(" is kept")[0])
    assert checkpoint.is_file() and checkpoint.parent == tmp_path / "run" / "checkpoints"
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_running(pid) for pid in workers):
        time.sleep(0.2)
    assert not [pid for pid in workers if _running(pid)], "worker processes were left behind"


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False
