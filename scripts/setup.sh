#!/usr/bin/env bash
# Create .venv and install dv2s-gym with its test tools. Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
step() { echo "setup: $*" >&2; }
step "1/4 creating .venv with $PY (if it does not exist yet)"
[ -x .venv/bin/python ] || "$PY" -m venv .venv
. .venv/bin/activate
python -m pip install -q --upgrade pip
# torch first, pinned: an unpinned torch pulls a multi-GB CUDA build.
step "2/4 installing PyTorch 2.13.0 (the CPU build)"
python -m pip install -q "torch==2.13.0"
# Editable: edits to the checkout take effect without reinstalling. Every extra: the tests, the LLM
# generator's retrieval, training, failure mining, Ray, and the documentation site (mkdocs).
# setuptools' notice about editable installs (a folder named like a package shadows it) is about this
# checkout, which is the package: it is silenced.
step "3/4 installing dv2s-gym and every extra (editable; a few minutes)"
PYTHONWARNINGS="ignore:Editable installation" python -m pip install -q -e ".[test,llm,rl,mining,ray,docs]"
# Scenic needs opencv-python; a second OpenCV distribution (e.g. -headless, pulled by
# some extras) would share the cv2/ folder. Keep exactly one.
for other in opencv-python-headless opencv-contrib-python opencv-contrib-python-headless; do
    if python -m pip show -q "$other" >/dev/null 2>&1; then
        python -m pip uninstall -q -y "$other"
        python -m pip install -q --force-reinstall --no-deps opencv-python
    fi
done
# System packages are installed with apt-get only when run as root, each announced first;
# DV2S_SETUP_SYSTEM=0 skips them (and prints the command to run instead).
SYSTEM=${DV2S_SETUP_SYSTEM:-1}
step "4/4 checking the system packages: bubblewrap, libseccomp2, chromium"
# The jail for untrusted Scenic: bubblewrap (unprivileged user namespaces) and libseccomp.
if ! command -v bwrap >/dev/null 2>&1; then
    if [ "$SYSTEM" != 0 ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing system packages with apt-get: bubblewrap libseccomp2 (DV2S_SETUP_SYSTEM=0 skips this)" >&2
        apt-get install -y -q --no-install-recommends bubblewrap libseccomp2 \
            || { apt-get update -q && apt-get install -y -q --no-install-recommends bubblewrap libseccomp2; }
    else
        echo "bubblewrap is missing: untrusted scenarios will be refused until it is installed." >&2
        echo "  Debian/Ubuntu: sudo apt-get install bubblewrap   Fedora: sudo dnf install bubblewrap" >&2
    fi
fi
# Headless Chromium from the system packages: the HTML regression report's browser test runs in it.
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1; then
    if [ "$SYSTEM" != 0 ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing system package with apt-get: chromium, for the HTML report's browser test (DV2S_SETUP_SYSTEM=0 skips this)" >&2
        apt-get update -q && apt-get install -y -q --no-install-recommends chromium
    else
        echo "Chromium is missing (needed by tests/test_regress_html.py): sudo apt-get update && sudo apt-get install -y --no-install-recommends chromium" >&2
    fi
fi
python -c "import cv2, scenic, highway_env, stable_baselines3, torch; print('dv2s-gym environment ready: cv2', cv2.__version__, 'torch', torch.__version__)"
python -c "from scenario_bank.jail import jail_status; ok, why = jail_status(); print('jail for untrusted Scenic:', 'ready' if ok else 'NOT available: ' + why)"
