"""The documentation: `mkdocs build --strict` builds the site with its API pages, and nothing a user reads
speaks of the project's internal history."""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
API_PAGES = {  # page -> objects its docstrings must document
    "api/envs": ["envs.dv2s_env.DV2SEnv", "envs.dv2s_env.DV2SEnv.default_config"],
    "api/bank": ["scenario_bank.bank.Bank", "scenario_bank.bank.Bank.add", "scenario_bank.list_scenarios",
                 "scenario_bank.records.Sidecar", "scenario_bank.records.Provenance",
                 "scenario_bank.records.EpisodeRecord"],
    "api/policies": ["policies.registry.load_policy", "policies.registry.register_policy"],
    "api/regress": ["dv2s_gym.regress.runner.run_regression"],
    "api/mining": ["dv2s_gym.mining.miner.mine", "dv2s_gym.loop.run.run_loop"],
}
# Internal history a user cannot follow: issue numbers, work sessions, numbered work periods, met targets,
# versions of the code a user never had.
HISTORY = re.compile(r"\bissue\s*#?\s*\d+|\bissues?\s+#\d+|#\d{1,3}\b(?![\w-])|\bbefore issue\b|\bnext issues?\b|"
                     r"\bwork (?:session|period)s?\b|\bperiod \d+\b|\bthe (?:issue's )?target is met\b|"
                     r"\bthe\s+earlier\s+(?:driver|default)\b|\ban\s+older\s+version\b|\bbefore\s+its\s+author\b|"
                     r"\bmeasured\s+with\s+different\s+versions\b", re.IGNORECASE)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"
    return out


@pytest.mark.slow  # the site takes 20-40 s to build
@pytest.mark.parametrize("page", sorted(API_PAGES))
def test_api_pages_document_the_public_api(site, page):
    text = (site / page / "index.html").read_text(encoding="utf-8")
    for name in API_PAGES[page]:
        assert f'id="{name}"' in text, f"{page} does not document {name}"
    assert "Args:" not in text  # Google-style sections were parsed, not shown as text


@pytest.mark.slow
def test_the_site_fetches_nothing_from_the_network(site):
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert "fonts.googleapis.com" not in text and "fonts.gstatic.com" not in text, page


def _user_pages():
    yield ROOT / "README.md"
    yield from sorted((ROOT / "docs").rglob("*.md"))


@pytest.mark.parametrize("page", list(_user_pages()), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_page_speaks_of_internal_history(page):
    text = page.read_text(encoding="utf-8")
    found = [m.group(0) for m in HISTORY.finditer(text)]
    assert not found, f"{page.relative_to(ROOT)} mentions {found}"


@pytest.mark.slow
def test_no_built_page_speaks_of_internal_history(site):
    for page in site.rglob("*.html"):
        text = html.unescape(re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8")))
        found = [m.group(0) for m in HISTORY.finditer(text)]
        assert not found, f"{page.relative_to(site)} mentions {found}"


def test_the_readme_opens_with_the_two_commands_and_its_pictures_exist():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```(\w*)\n(.*?)```", readme, re.DOTALL)
    assert [b[1].strip() for b in blocks[:2]] == ["./scripts/setup.sh && .venv/bin/dv2s loop",
                                                  ".venv/bin/python -m pytest -q -n 2"]
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", readme)
    assert pictures and readme.index(pictures[0]) < readme.index("./scripts/setup.sh")
    for picture in pictures:
        assert (ROOT / picture).is_file(), picture
    assert sum((ROOT / p).stat().st_size for p in pictures) < 1_000_000


def test_the_readme_regress_picture_is_made_by_the_command_above_it():
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from make_readme_pictures import REGRESS_ARGS
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    command = re.search(r"^dv2s regress (.*) --out out/regress$", readme, re.MULTILINE)
    assert command, "the README shows no `dv2s regress ... --out out/regress` command"
    shown = command.group(1).split()
    picture_only = {"--workers": "1", "--no-progress": None}  # how the picture is made, not what it shows
    made = []
    args = iter(REGRESS_ARGS)
    for arg in args:
        if arg in picture_only:
            if picture_only[arg] is not None:
                next(args)
            continue
        made.append(arg)
    assert shown == made


BANK_COUNT = re.compile(r"\b(\d+)[- ]scenario (?:shipped )?bank\b|\ball (\d+) scenarios\b|\bthe (\d+) scenarios\b",
                        re.IGNORECASE)


@pytest.mark.parametrize("page", list(_user_pages()), ids=lambda p: str(p.relative_to(ROOT)))
def test_a_count_of_the_bank_is_the_shipped_banks(page):
    from scenario_bank import list_scenarios

    size = len(list_scenarios())
    counts = [next(g for g in m.groups() if g) for m in BANK_COUNT.finditer(page.read_text(encoding="utf-8"))]
    assert all(int(count) == size for count in counts), f"{page.relative_to(ROOT)} counts {counts}; the bank has {size}"
