"""Score the description parser (``elements_from_text``) against labelled descriptions.

Usage::

    python scripts/parser_vs_labels.py dv2s_gym/evalset/descriptions [--per-item] [--by-kind]

Reads every labelled description under the folder (JSON objects, JSON lists or
JSONL lines holding a description text -- ``description``/``text`` -- and its
elements -- ``elements``/``label``/``labels``; or ``NAME.txt`` beside
``NAME.json``/``NAME.label.json``) and prints, over all of them, the mean SCS
(recall of label elements in the parse), the mean HR (share of parsed elements
not in the label) and the micro recall/precision, per element kind with
``--by-kind``. Run it with ``PYTHONPATH`` pointing at another checkout to
score that checkout's parser on the same labels ("before" vs "after").
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any, Dict, Iterator, List, Tuple

from dv2s_gym.pipeline.metrics import hallucination_rate, scs
from dv2s_gym.pipeline.semantics import elements_from_text
from scenario_bank.elements import element_set, with_undirected

_TEXT_KEYS = ("description", "text")
_LABEL_KEYS = ("elements", "label", "labels")


def _items_from(obj: Any, name: str) -> Iterator[Tuple[str, str, Dict[str, Any]]]:
    if isinstance(obj, list):
        for i, o in enumerate(obj):
            yield from _items_from(o, f"{name}[{i}]")
    elif isinstance(obj, dict):
        text = next((obj[k] for k in _TEXT_KEYS if isinstance(obj.get(k), str)), None)
        label = next((obj[k] for k in _LABEL_KEYS if isinstance(obj.get(k), dict)), None)
        if text is not None and label is not None:
            yield str(obj.get("id") or obj.get("name") or name), text, label
        else:
            for k, v in obj.items():
                if isinstance(v, (list, dict)):
                    yield from _items_from(v, f"{name}/{k}")


def load(folder: Path) -> List[Tuple[str, str, Dict[str, Any]]]:
    """(name, description, label elements) of every labelled description under ``folder``."""
    items: List[Tuple[str, str, Dict[str, Any]]] = []
    for path in sorted(folder.rglob("*")):
        if path.suffix == ".jsonl":
            for i, line in enumerate(path.read_text().splitlines()):
                if line.strip():
                    items.extend(_items_from(json.loads(line), f"{path.name}:{i}"))
        elif path.suffix == ".json":
            data = json.loads(path.read_text())
            found = list(_items_from(data, path.stem))
            if not found and isinstance(data, dict):
                txt = path.with_name(path.name.replace(".label.json", ".txt").replace(".json", ".txt"))
                label = next((data[k] for k in _LABEL_KEYS if isinstance(data.get(k), dict)), None)
                if label is None:
                    label = {k: data[k] for k in ("road", "participants", "actions", "relations") if k in data}
                if txt.exists():
                    found = [(path.stem, txt.read_text(), label)]
            items.extend(found)
    return items


def main(argv: List[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--per-item", action="store_true", help="print each item's misses and extras")
    ap.add_argument("--by-kind", action="store_true", help="micro recall/precision per element kind")
    args = ap.parse_args(argv)
    items = load(args.folder)
    if not items:
        print(f"no labelled descriptions found under {args.folder}", file=sys.stderr)
        return 2
    scs_all, hr_all = [], []
    hit, said, found = Counter(), Counter(), Counter()
    for name, text, label in items:
        got = elements_from_text(text)
        truth, parsed = element_set(label), element_set(got)
        scs_all.append(scs(truth, parsed))
        hr_all.append(hallucination_rate(truth, parsed))
        parsed_w, truth_w = with_undirected(parsed), with_undirected(truth)
        for e in truth:
            said[e[0]] += 1
            hit[e[0]] += e in parsed_w
        for e in parsed:
            found[e[0]] += 1
        if args.per_item:
            print(f"{name}: SCS {scs_all[-1]:.2f} HR {hr_all[-1]:.2f}")
            print(f"   missed: {sorted(truth - parsed_w)}")
            print(f"   extra:  {sorted(parsed - truth_w)}")
    n = len(items)
    print(f"items {n}  mean SCS {sum(scs_all) / n:.3f}  mean HR {sum(hr_all) / n:.3f}  "
          f"micro recall {sum(hit.values()) / max(1, sum(said.values())):.3f}")
    if args.by_kind:
        for kind in sorted(said):
            print(f"   {kind:12s} recall {hit[kind] / said[kind]:.3f} ({hit[kind]}/{said[kind]})  parsed {found[kind]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
