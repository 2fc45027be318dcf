"""The core install: what the README promises works without the extras does, and what needs an extra says which.

The extras' modules (PyTorch, stable-baselines3, VerifAI, Ray...) are hidden from a child interpreter by an
import hook, as if only ``pip install .`` had run; the commands then run in it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dv2s_gym.cli.errors import EXTRA_OF_MODULE, error_line, missing_extra

HIDE_EXTRAS = textwrap.dedent(f"""
    import sys

    HIDDEN = {sorted(EXTRA_OF_MODULE)!r}

    class _NotInstalled:
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in HIDDEN:
                raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
            return None

    sys.meta_path.insert(0, _NotInstalled())

    if __name__ == "__main__":
        from dv2s_gym.cli import main
        sys.exit(main(sys.argv[1:]))
    """)


def _core(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    script = tmp_path / "core_only.py"
    script.write_text(HIDE_EXTRAS)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, str(script), *args], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)


def test_a_missing_extra_is_named_with_the_command_that_installs_it():
    error = ModuleNotFoundError("No module named 'stable_baselines3'", name="stable_baselines3.common")
    assert missing_extra(error) == "rl"
    assert "pip install 'dv2s-gym[rl]'" in error_line(error) and "stable_baselines3" in error_line(error)
    assert missing_extra(ModuleNotFoundError("No module named 'yaml'", name="yaml")) == ""
    assert missing_extra(ImportError("cannot import name 'x'")) == ""


@pytest.mark.slow
def test_the_env_runs_without_the_extras(tmp_path):
    code = HIDE_EXTRAS.replace('if __name__ == "__main__":', "if False:") + textwrap.dedent("""
        import gymnasium as gym
        env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_lead_vehicle_brakes", config={"duration": 1})
        obs, info = env.reset(seed=0)
        for _ in range(3):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        hidden = sorted(m for m in sys.modules if m.partition(".")[0] in HIDDEN)
        print("ok", info["scenario"], hidden)
        """)
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, OMP_NUM_THREADS="1"))
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "ok highway_lead_vehicle_brakes []"


@pytest.mark.slow
def test_the_core_commands_run_without_the_extras(tmp_path):
    listed = _core(tmp_path, "bank", "list")
    assert listed.returncode == 0 and "scenario(s)" in listed.stdout, listed.stderr[-2000:]
    ran = _core(tmp_path, "run", "urban_pull_back_in", "--duration", "1", "--seed", "0")
    assert ran.returncode == 0 and "outcome:" in ran.stdout, ran.stderr[-2000:]
    regress = _core(tmp_path, "regress", "--policy", "keep_lane", "--baseline", "rule", "--scenarios",
                    "urban_pull_back_in", "--episodes", "1", "--workers", "1", "--out", str(tmp_path / "reg"),
                    "--no-progress")
    assert regress.returncode in (0, 1, 3), regress.stderr[-2000:]
    assert (tmp_path / "reg" / "report.json").is_file()


@pytest.mark.parametrize("args, extra", [
    (["train", "--steps", "10", "--out", "run"], "rl"),
    (["mine", "--policy", "rule", "--budget", "2", "--no-convert", "--out", "mined"], "mining"),
])
def test_a_command_that_needs_an_extra_says_which_in_one_line(tmp_path, args, extra):
    out = _core(tmp_path, *args)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert f"pip install 'dv2s-gym[{extra}]'" in lines[0] and "--debug" not in lines[0]
