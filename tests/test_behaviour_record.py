"""The rules SG's behaviour, recorded: what it writes for every description the repository ships.

The digests in ``tests/data/behaviour/rules_sg.json`` are the SHA-256 of the elements the description parser reads
and of the script, warnings and elements the rules SG generates with seeds 0 and 1, for the description of every
shipped bank scenario and every description of the in-house evaluation set. A refactor must leave them all as they
are; a change of behaviour meant to be one changes them, and is recorded by writing them again:

    .venv/bin/python tests/test_behaviour_record.py --write
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path
from typing import Dict

from dv2s_gym.pipeline.sg.rules import generate_rules
from dv2s_gym.pipeline.semantics.text import elements_from_text

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "tests" / "data" / "behaviour" / "rules_sg.json"
SEEDS = (0, 1)


def _descriptions() -> Dict[str, str]:
    """``{name: description}``: each shipped bank scenario's and each in-house evaluation-set description."""
    found = {}
    for meta in sorted((ROOT / "scenario_bank" / "scenarios").glob("*/meta.json")):
        found[f"bank/{meta.parent.name}"] = json.loads(meta.read_text(encoding="utf-8"))["description"]
    for text in sorted((ROOT / "dv2s_gym" / "evalset" / "descriptions").glob("*.txt")):
        found[f"evalset/{text.stem}"] = text.read_text(encoding="utf-8")
    return found


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode("utf-8")).hexdigest()


def behaviour() -> Dict[str, Dict[str, str]]:
    """The digests of what the parser and the rules SG make of every shipped description."""
    record = {}
    for name, text in _descriptions().items():
        row = {"elements": _digest(elements_from_text(text).to_dict())}
        for seed in SEEDS:
            result = generate_rules(text, seed=seed)
            row[f"seed{seed}"] = _digest([result.script, list(result.warnings), result.elements.to_dict()])
        record[name] = row
    return record


def test_the_rules_sg_writes_what_it_wrote_for_every_shipped_description():
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))
    now = behaviour()
    assert len(now) >= 150 and set(now) == set(recorded), "descriptions added or gone: write the record again"
    changed = sorted(name for name in now if now[name] != recorded[name])
    assert not changed, (f"the parser or the rules SG now makes something else of {len(changed)} description(s): "
                         f"{changed[:10]}; if the change is meant, record it: python tests/test_behaviour_record.py "
                         "--write")


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    RECORD.parent.mkdir(parents=True, exist_ok=True)
    RECORD.write_text(json.dumps(behaviour(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {RECORD}")
