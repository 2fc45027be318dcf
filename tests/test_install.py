"""The installed environment: an editable install, one working OpenCV, the CLI, and
``gym.make("dv2s_gym:DV2S-v0")`` in a fresh process with no import."""

import importlib.metadata as md
import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

OPENCV_DISTS = ("opencv-python", "opencv-python-headless", "opencv-contrib-python", "opencv-contrib-python-headless")


def test_exactly_one_opencv_distribution_and_it_works(tmp_path):
    installed = []
    for name in OPENCV_DISTS:
        try:
            md.distribution(name)
            installed.append(name)
        except md.PackageNotFoundError:
            pass
    assert installed == ["opencv-python"], f"OpenCV distributions installed: {installed}"
    import cv2

    path = str(tmp_path / "probe.webm")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"VP80"), 10, (64, 48))
    assert writer.isOpened()
    for i in range(5):
        writer.write(np.full((48, 64, 3), 40 * i, np.uint8))
    writer.release()
    capture = cv2.VideoCapture(path)
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert frames == 5


def test_cli_help_for_every_subcommand():
    from dv2s_gym.cli import build_parser

    parser = build_parser()
    commands = [["--help"], ["demo", "--help"], ["run", "--help"], ["replay", "--help"], ["maps", "--help"],
                ["bank", "--help"], ["bank", "list", "--help"]]
    for argv in commands:
        with pytest.raises(SystemExit) as exit_info:
            parser.parse_args(argv)
        assert exit_info.value.code == 0, argv


def test_cli_reports_unknown_scenario_cleanly(capsys):
    from dv2s_gym.cli import main

    assert main(["run", "highway_lead_vehicle_brake", "--video", os.devnull + ".webm"]) == 2
    err = capsys.readouterr().err
    assert "unknown scenario" in err and "highway_lead_vehicle_brakes" in err


def _distribution():
    """dv2s-gym's installed metadata in site-packages (not the egg-info an editable build leaves in the checkout)."""
    site = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    return next(iter(md.distributions(name="dv2s-gym", path=site)), None)


installed = pytest.mark.skipif(_distribution() is None, reason="dv2s-gym is not pip-installed in this environment")


@installed
def test_the_install_is_editable_and_points_at_this_checkout():
    """``pip install -e .`` (scripts/setup.sh): the installed package is this checkout, no copy, no .pth hook."""
    dist = _distribution()
    direct_url = json.loads(dist.read_text("direct_url.json") or "{}")
    assert direct_url.get("dir_info", {}).get("editable") is True, direct_url
    checkout = Path(direct_url["url"].removeprefix("file://")).resolve()
    code = "import dv2s_gym, pathlib; print(pathlib.Path(dv2s_gym.__file__).resolve().parent.parent)"
    out = subprocess.run([sys.executable, "-c", code], cwd="/", env=_clean_env(), capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert Path(out.stdout.strip()) == checkout
    site = Path(md.distribution("gymnasium").locate_file(""))
    assert not list(site.glob("dv2s_gym_autoregister*")) and not (site / "_dv2s_gym_autoregister.py").exists()


def _clean_env():
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


@pytest.mark.slow
@installed
def test_gym_make_with_the_module_prefix_needs_no_import(tmp_path):
    """Gymnasium's idiom: ``gym.make("dv2s_gym:DV2S-v0")`` imports dv2s_gym itself, which registers."""
    code = (
        "import gymnasium as gym, sys\n"
        "assert 'dv2s_gym' not in sys.modules\n"
        "env = gym.make('dv2s_gym:DV2S-v0', scenario='urban_pull_back_in', config={'duration': 1})\n"
        "obs, info = env.reset(seed=0)\n"
        "print(info['scenario'])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_clean_env(), capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("urban_pull_back_in")


@installed
def test_console_script_help():
    dv2s = Path(sys.executable).with_name("dv2s")
    assert dv2s.is_file(), "the dv2s console script is not installed"
    out = subprocess.run([str(dv2s), "--help"], env=_clean_env(), capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "usage: dv2s" in out.stdout and "bank" in out.stdout


def test_import_registers_the_env():
    import gymnasium as gym

    import dv2s_gym  # noqa: F401

    assert "DV2S-v0" in gym.registry
    assert gym.registry["DV2S-v0"].entry_point == "envs.registration:make_env"
