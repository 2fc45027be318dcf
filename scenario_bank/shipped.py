"""Which scripts ship with the package, by content hash: only these may run outside the jail.

``shipped_scenarios.sha256`` (beside this module) lists the SHA-256 of every
shipped bank script's text. A script whose text hashes to one of them is the
package's own and runs in the user's process (fast); any other text, a bank
script edited in place included, is untrusted and runs in the jail. After
changing a shipped script, regenerate the list with
``python -m scenario_bank.shipped`` (a test checks that it is current).
"""

from __future__ import annotations

import hashlib
import sys
from functools import lru_cache
from pathlib import Path
from typing import FrozenSet

__all__ = ["MANIFEST", "is_shipped_text", "text_digest", "shipped_digests", "write_manifest"]

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


if __name__ == "__main__":
    print(write_manifest())
    sys.exit(0)
