"""How often the loop's per-family harm rule blocks ACCEPTED, by simulation of the held-out pairs.

    python -m bench.research.loop_harm_rule
    python -m bench.research.loop_harm_rule --families 6 --pairs 16 --discordant 0.31 --trials 2000

``dv2s loop`` does not accept a round's fine-tuned policy when, in any held-out family, a harm against the control
is not ruled out (:func:`dv2s_gym.loop.verdict.family_harm`). This script draws paired held-out tables for a
fine-tuned policy against a control whose differences are known (each pair discordant with probability
``--discordant``; a discordant pair is a failure of the fine-tuned policy only with probability ``share``, of the
control only otherwise) and counts how often the product's own ``family_harm`` names a harmed family. With
``share = 0.5`` the two policies are equal; below 0.5 the fine-tuned policy is the better one in every family, so
every block is a false one. It prints one line per (families, pairs per family, share) with the blocking rate and its
95 % Wilson interval.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Dict, Sequence

import numpy as np

from dv2s_gym.loop.settings import LoopSettings
from dv2s_gym.loop.verdict import family_harm
from dv2s_gym.regress.stats import PairedTable


def draw_tables(rng: np.random.Generator, families: int, pairs: int, discordant: float, share: float,
                both_fail: float) -> Dict[str, PairedTable]:
    """One held-out result: ``{family: PairedTable}`` with ``pairs`` pairs in each of ``families`` families."""
    tables = {}
    for f in range(families):
        kind = rng.random(pairs)
        n_disc = int((kind < discordant).sum())
        n_both = int(((kind >= discordant) & (kind < discordant + both_fail)).sum())
        candidate_only = int(rng.binomial(n_disc, share))
        tables[f"family{f}"] = PairedTable(both_fail=n_both, candidate_only=candidate_only,
                                           baseline_only=n_disc - candidate_only,
                                           neither=pairs - n_disc - n_both)
    return tables


def wilson(k: int, n: int, z: float = 1.96) -> Sequence[float]:
    """Wilson score interval of a proportion."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def blocking_rate(rng: np.random.Generator, families: int, pairs: int, discordant: float, share: float,
                  both_fail: float, margin: float, trials: int) -> Dict[str, object]:
    """The share of ``trials`` simulated rounds in which ``family_harm`` names at least one harmed family."""
    blocked = sum(bool(family_harm(draw_tables(rng, families, pairs, discordant, share, both_fail), margin).harmed)
                  for _ in range(trials))
    low, high = wilson(blocked, trials)
    return {"families": families, "pairs_per_family": pairs, "discordant": discordant, "share": share,
            "margin": margin, "trials": trials, "blocked": blocked / trials, "interval": [round(low, 3), round(high, 3)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--families", type=int, nargs="+", default=[6, 10])
    parser.add_argument("--pairs", type=int, nargs="+", default=[10, 16, 30, 100],
                        help="pairs per held-out family (the evidence profile gives 10-17)")
    parser.add_argument("--share", type=float, nargs="+", default=[0.5, 0.4, 0.3],
                        help="share of the discordant pairs where only the fine-tuned policy fails")
    parser.add_argument("--discordant", type=float, default=0.31,
                        help="probability a pair is discordant (0.31 in the evidence round on the better base)")
    parser.add_argument("--both-fail", type=float, default=0.45, help="probability both policies fail a pair")
    parser.add_argument("--margin", type=float, default=LoopSettings().margin)
    parser.add_argument("--trials", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    for families in args.families:
        for pairs in args.pairs:
            for share in args.share:
                print(json.dumps(blocking_rate(rng, families, pairs, args.discordant, share, args.both_fail,
                                               args.margin, args.trials)), flush=True)


if __name__ == "__main__":
    main()
