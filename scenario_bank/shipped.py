"""Which scripts ship with the package, by content hash: only these may run outside the jail.

``shipped_scenarios.sha256`` (beside this module) lists the SHA-256 of every
shipped bank script's text. A script whose text hashes to one of them is the
package's own and runs in the user's process (fast); any other text, a bank
script edited in place included, is untrusted and runs in the jail. After
changing a shipped script, regenerate the list with
``python -m scenario_bank.shipped``; it also brings each shipped sidecar's
``content_hash`` up to date (a test checks that both are current).
"""

from __future__ import annotations

import hashlib
import json
import sys
from functools import lru_cache
from pathlib import Path
from typing import FrozenSet, List

__all__ = ["MANIFEST", "is_shipped_text", "text_digest", "shipped_digests", "write_manifest", "stale_sidecars",
           "refresh_sidecars"]

MANIFEST = Path(__file__).resolve().parent / "shipped_scenarios.sha256"
_SCENARIOS = Path(__file__).resolve().parent / "scenarios"


def text_digest(text: str) -> str:
    """The SHA-256 of a script's text (UTF-8)."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@lru_cache(maxsize=1)
def shipped_digests() -> FrozenSet[str]:
    """The digests the manifest lists (empty when it is missing: then nothing is trusted)."""
    try:
        lines = MANIFEST.read_text(encoding="ascii").splitlines()
    except (OSError, UnicodeDecodeError):
        return frozenset()
    return frozenset(line.split()[0] for line in lines if line.strip() and not line.startswith("#"))


def is_shipped_text(text: str) -> bool:
    """Whether ``text`` is exactly one of the shipped bank scripts."""
    return text_digest(text) in shipped_digests()


def manifest_text() -> str:
    """The manifest the shipped scripts on disk give (what :func:`write_manifest` writes)."""
    rows = []
    for script in sorted(_SCENARIOS.glob("*/scenario.scenic")):
        rows.append(f"{text_digest(script.read_text(encoding='utf-8'))}  {script.parent.name}")
    return "# SHA-256 of each shipped bank script: these run outside the jail. python -m scenario_bank.shipped\n" + \
        "\n".join(rows) + "\n"


def write_manifest() -> Path:
    """Rewrite the manifest from the shipped scripts."""
    MANIFEST.write_text(manifest_text(), encoding="ascii")
    shipped_digests.cache_clear()
    return MANIFEST


def stale_sidecars() -> List[Path]:
    """The shipped sidecars (``meta.json``) whose ``content_hash`` is not their script's digest."""
    stale = []
    for script in sorted(_SCENARIOS.glob("*/scenario.scenic")):
        sidecar = script.parent / "meta.json"
        meta = json.loads(sidecar.read_text(encoding="utf-8"))
        if meta.get("content_hash") != text_digest(script.read_text(encoding="utf-8")):
            stale.append(sidecar)
    return stale


def refresh_sidecars() -> List[Path]:
    """Write each stale shipped sidecar's ``content_hash`` from its script; return the sidecars rewritten.

    Only that one field changes; the file keeps the bank's JSON layout (sorted keys, two-space indent).
    """
    rewritten = stale_sidecars()
    for sidecar in rewritten:
        meta = json.loads(sidecar.read_text(encoding="utf-8"))
        meta["content_hash"] = text_digest((sidecar.parent / "scenario.scenic").read_text(encoding="utf-8"))
        sidecar.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return rewritten


if __name__ == "__main__":
    for path in refresh_sidecars():
        print(f"content_hash updated: {path}")
    print(write_manifest())
    sys.exit(0)
