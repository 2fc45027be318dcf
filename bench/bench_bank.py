"""Scenario bank speed: list/filter a 10,000-entry bank, open the shipped bank.

    python -m bench.bench_bank

Targets: listing and filtering 10,000 entries under 1 s; opening the
shipped bank under 0.5 s. The 10,000 entries are written straight to disk
(copies of shipped scenarios with varied parameters and tags), then opened twice:
cold (index rebuilt from every sidecar) and warm (index up to date).
"""

from __future__ import annotations

import json
import random
import tempfile
import time
from pathlib import Path

from scenario_bank.bank import SCRIPT, SIDECAR, Bank, content_hash

N = 10_000


def build(root: Path, n: int = N) -> None:
    shipped = list(Bank())
    if not shipped:
        raise SystemExit("the shipped bank is empty")
    rng = random.Random(0)
    for i in range(n):
        base = shipped[i % len(shipped)]
        script = base.script + f"\nparam bench_{i} = Range({i}, {i + rng.randint(1, 9)})\n"
        meta = dict(base.sidecar.to_dict(), name=f"s{i:05d}", content_hash=content_hash(script),
                    tags=base.tags + [f"batch{i % 50}"])
        folder = root / meta["name"]
        folder.mkdir(parents=True)
        (folder / SCRIPT).write_text(script)
        (folder / SIDECAR).write_text(json.dumps(meta))


def timed(fn):
    start = time.perf_counter()
    value = fn()
    return value, time.perf_counter() - start


def main() -> None:
    _, t_ship = timed(lambda: Bank())
    _, t_ship_warm = timed(lambda: Bank())
    print(f"open shipped bank ({len(Bank())} entries): first {t_ship:.3f} s, again {t_ship_warm:.3f} s (target < 0.5 s)")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "bank"
        build(root)
        bank, cold = timed(lambda: Bank(root))
        bank, warm = timed(lambda: Bank(root))
        listed, t_list = timed(lambda: bank.list())
        tagged, t_tag = timed(lambda: bank.list(tag="batch7"))
        texted, t_text = timed(lambda: bank.list(text="pedestrian"))
        elem, t_elem = timed(lambda: bank.list(element=["car:cut_in", "ahead_of"]))
        print(f"{N} entries: open cold (index rebuilt) {cold:.3f} s, open warm {warm:.3f} s")
        print(f"    list all {len(listed)}: {t_list * 1000:.1f} ms; by tag {len(tagged)}: {t_tag * 1000:.1f} ms; "
              f"by text {len(texted)}: {t_text * 1000:.1f} ms; by element {len(elem)}: {t_elem * 1000:.1f} ms")
        print(f"    open warm + list + three filters: {warm + t_list + t_tag + t_text + t_elem:.3f} s (target < 1 s)")


if __name__ == "__main__":
    main()
