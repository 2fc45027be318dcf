"""Score the description parser (``elements_from_text``) against labelled descriptions.

Usage::

    python scripts/parser_vs_labels.py dv2s_gym/evalset/descriptions [--per-item] [--by-kind]

Reads every labelled description of the folder as ``dv2s eval sg`` does
(``NAME.txt`` beside ``NAME.label.json``, either label format:
:func:`dv2s_gym.pipeline.evaluate.collect_items`) and prints, over all of them, the mean SCS
(recall of label elements in the parse), the mean HR (share of parsed elements
not in the label) and the micro recall/precision, per element kind with
``--by-kind``. Run it with ``PYTHONPATH`` pointing at another checkout to
score that checkout's parser on the same labels ("before" vs "after").
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path
from typing import List

from dv2s_gym.pipeline.evaluate import collect_items
from dv2s_gym.pipeline.metrics import hallucination_rate, scs
from dv2s_gym.pipeline.semantics.text import elements_from_text
from scenario_bank.elements import element_set, with_undirected

def main(argv: List[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--per-item", action="store_true", help="print each item's misses and extras")
    ap.add_argument("--by-kind", action="store_true", help="micro recall/precision per element kind")
    args = ap.parse_args(argv)
    try:
        items = [item for item in collect_items(args.folder) if item.description]
    except FileNotFoundError as error:
        print(error, file=sys.stderr)
        return 2
    scs_all, hr_all = [], []
    hit, said, found = Counter(), Counter(), Counter()
    for item in items:
        name = item.stem
        truth, parsed = element_set(item.elements), element_set(elements_from_text(item.description))
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
