"""Make the pictures the README and the documentation show, into docs/img/.

    python scripts/make_readme_pictures.py              # both pictures
    python scripts/make_readme_pictures.py --only episode

* ``episode.gif``: one episode of a bank scenario (a left turn across oncoming cars, the rule-based
  driver as the ego, rendered offscreen by highway-env's viewer), every second frame, palette-reduced.
* ``regress.png``: the HTML page ``dv2s regress`` writes, for a small run of two built-in policies on
  two scenarios, screenshotted by headless Chromium (Debian's ``chromium``), with its settings and
  scenario tables left out so that the verdict, the plots and the first clips fit one picture.

Run from the repository root with the project's virtual environment; it needs no network. The
pictures are small (under 1 MB together) so they can be committed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")  # no window: highway-env renders into a surface

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "img"

EPISODE_SCENARIO = "urban_left_turn_oncoming"
EPISODE_SEED = 0
REGRESS_ARGS = ["--policy", "keep_lane", "--baseline", "rule", "--scenarios", "highway_lead_vehicle_brakes",
                "urban_pedestrian_crossing", "--episodes", "6", "--workers", "1", "--no-progress"]


def episode_gif(path: Path, scenario: str = EPISODE_SCENARIO, seed: int = EPISODE_SEED, width: int = 480,
                height: int = 320, scaling: float = 5.0, every: int = 2, colours: int = 64) -> Path:
    """One episode of ``scenario`` driven by the rule-based driver, as an animated GIF (``scaling`` pixels
    per metre, the view centred on the ego)."""
    import gymnasium as gym
    from PIL import Image

    import dv2s_gym  # noqa: F401  (registers DV2S-v0)
    from policies import CautiousDriver

    env = gym.make("dv2s_gym:DV2S-v0", scenario=scenario, render_mode="rgb_array",
                   config={"offscreen_rendering": True, "screen_width": width, "screen_height": height,
                           "scaling": scaling})
    driver = CautiousDriver(env)
    obs, info = env.reset(seed=seed)
    frames, done = [env.render()], False
    while not done:
        obs, _, terminated, truncated, info = env.step(driver(obs, info))
        frames.append(env.render())
        done = terminated or truncated
    env.close()
    images = [Image.fromarray(frame) for frame in frames[::every]]
    palette = images[len(images) // 2].quantize(colors=colours, method=Image.Quantize.MEDIANCUT)
    quantized = [image.quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
    path.parent.mkdir(parents=True, exist_ok=True)
    fps = env.unwrapped.config.get("policy_frequency", 5) / every
    quantized[0].save(path, save_all=True, append_images=quantized[1:], duration=int(1000 / fps), loop=0,
                      optimize=True)
    return path


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    sys.exit("make_readme_pictures: Chromium is needed for the regression page's screenshot: "
             "sudo apt-get install -y --no-install-recommends chromium (or run scripts/setup.sh as root)")


_LEAVE_OUT = """<script>window.addEventListener("load", function () {
  document.querySelectorAll("h2").forEach(function (heading) {
    if (["Settings", "Scenarios"].indexOf(heading.textContent) < 0) { return; }
    var next = heading.nextElementSibling;
    while (next && next.tagName !== "H2") { var gone = next; next = next.nextElementSibling; gone.remove(); }
    heading.remove();
  });
});</script>"""


def regress_png(path: Path, width: int = 1100, height: int = 1000, colours: int = 96) -> Path:
    """A small ``dv2s regress`` run's HTML page without its settings and scenario tables, as a palette PNG."""
    from PIL import Image

    browser = _chromium()
    with tempfile.TemporaryDirectory(prefix="dv2s-pictures-") as tmp:
        run = Path(tmp) / "regress"
        command = [sys.executable, "-m", "dv2s_gym.cli", "regress", *REGRESS_ARGS, "--out", str(run)]
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode not in (0, 1, 3):  # PASS, FAIL, INCONCLUSIVE all make a page
            sys.exit(f"make_readme_pictures: dv2s regress failed (exit {done.returncode}): {done.stderr[-2000:]}")
        page = run / "picture.html"
        page.write_text((run / "report.html").read_text().replace("</body>", _LEAVE_OUT + "</body>"))
        shot = Path(tmp) / "page.png"
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                        f"--user-data-dir={Path(tmp) / 'profile'}", "--hide-scrollbars",
                        f"--window-size={width},{height}", "--virtual-time-budget=3000",
                        f"--screenshot={shot}", page.as_uri()],
                       capture_output=True, text=True, timeout=300, check=True)
        image = Image.open(shot).convert("RGB")
    path.parent.mkdir(parents=True, exist_ok=True)
    image.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(path, optimize=True)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["episode", "regress"], help="make only this picture")
    parser.add_argument("--out", type=Path, default=OUT, help="folder (default: docs/img)")
    args = parser.parse_args(argv)
    made = []
    if args.only in (None, "episode"):
        made.append(episode_gif(args.out / "episode.gif"))
    if args.only in (None, "regress"):
        made.append(regress_png(args.out / "regress.png"))
    for path in made:
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {path.stat().st_size / 1024:.0f} KiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
