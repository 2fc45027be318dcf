"""Pair two fine-tuning arms of one ``dv2s loop`` round on the round's held-out episodes.

    python -m bench.research.loop_sweep_pair --loop /work/exp/loop_ev2 \\
        --a /work/exp/sweep/ft_beta0 --b /work/exp/sweep/ctl_beta0
    python -m bench.research.loop_sweep_pair --loop /work/exp/loop_ev2 --a /work/exp/sweep/ft_beta0 --b loop:control

An arm is a finished :mod:`bench.research.loop_finetune_sweep` folder (its ``heldout.jsonl``, role ``after``) or
one of the loop's own arms (``loop:after`` the fine-tuned arm, ``loop:control`` the control, ``loop:before`` the
starting policy; the round's ``heldout.jsonl``). The episodes are the round's: every held-out scenario with
seeds ``EVAL_SEED_BASE + 0 .. k_eval - 1``, matched by (scenario, seed); a pair with an error on either side, or
an episode one arm has not run, is left out and counted. Prints (or with ``--json`` returns) the failure counts,
the paired table (``a_only``: A failed and B did not), the exact two-sided McNemar p, the same per held-out family
(:func:`dv2s_gym.mining.family.scenario_family` in the loop's working bank) and each arm's failure types.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

from scenario_bank.records import HeldOutEpisode


def loop_episodes(loop: Path) -> Tuple[List[Tuple[str, int]], str]:
    """The round-1 held-out episodes of ``loop`` and its working bank."""
    from policies.training import EVAL_SEED_BASE

    state = json.loads((loop / "loop.json").read_text(encoding="utf-8"))
    held = state["rounds"][0]["steps"]["split"]["held_out"]
    k = state["settings"]["k_eval"]
    return [(name, EVAL_SEED_BASE + i) for name in held for i in range(k)], state["start"]["bank"]


def arm_records(loop: Path, arm: str, episodes: Sequence[Tuple[str, int]]) -> List[Optional[HeldOutEpisode]]:
    """The records of ``arm`` (a sweep folder or ``loop:<role>``) on ``episodes``, ``None`` where one is missing."""
    from dv2s_gym.loop.heldout import HeldOutStore

    if arm.startswith("loop:"):
        store, role = HeldOutStore(loop / "round_1" / "heldout.jsonl"), arm.split(":", 1)[1]
    else:
        store, role = HeldOutStore(Path(arm) / "heldout.jsonl"), "after"
    return [store.get(role, name, seed) for name, seed in episodes]


def table_of(outcomes: Sequence[Tuple[bool, bool]]) -> Dict[str, Any]:
    """Counts and exact two-sided McNemar p of (A failed, B failed) pairs."""
    from dv2s_gym.regress.stats import PairedTable, mcnemar_exact

    table = PairedTable.from_outcomes([a for a, _ in outcomes], [b for _, b in outcomes])
    return {"pairs": len(outcomes), "a_failed": sum(a for a, _ in outcomes), "b_failed": sum(b for _, b in outcomes),
            "both_fail": table.both_fail, "a_only": table.candidate_only, "b_only": table.baseline_only,
            "neither": table.neither, "mcnemar_p": mcnemar_exact(table) if outcomes else None}


def failure_kind(record: HeldOutEpisode) -> Optional[str]:
    """``stall``, ``collision`` or ``other`` (off road, low TTC) for a failed record; ``None`` when it passed."""
    if not record.failed:
        return None
    kind = (record.failure or {}).get("type")
    return kind if kind in ("stall", "collision") else "other"


def pair_arms(loop: Path, a: str, b: str) -> Dict[str, Any]:
    """Arm ``a`` against arm ``b`` on the held-out episodes of ``loop`` (see the module docstring)."""
    from dv2s_gym.mining.family import scenario_family
    from dv2s_gym.loop.heldout import episode_failed

    episodes, bank = loop_episodes(loop)
    recs_a, recs_b = arm_records(loop, a, episodes), arm_records(loop, b, episodes)
    missing = errors = 0
    pairs: List[Tuple[str, bool, bool, HeldOutEpisode, HeldOutEpisode]] = []
    for (name, _seed), ra, rb in zip(episodes, recs_a, recs_b):
        if ra is None or rb is None:
            missing += 1
            continue
        fa, fb = episode_failed(ra), episode_failed(rb)
        if fa is None or fb is None:
            errors += 1
            continue
        pairs.append((name, fa, fb, ra, rb))
    family = {name: scenario_family(name, bank) for name in {p[0] for p in pairs}}
    per_family = {}
    for fam in sorted(set(family.values())):
        per_family[fam] = table_of([(fa, fb) for name, fa, fb, _, _ in pairs if family[name] == fam])
    return {"loop": str(loop), "a": a, "b": b, "episodes": len(episodes), "missing": missing, "errors": errors,
            **table_of([(fa, fb) for _, fa, fb, _, _ in pairs]),
            "kinds_a": dict(Counter(failure_kind(ra) for *_, ra, _ in pairs if ra.failed)),
            "kinds_b": dict(Counter(failure_kind(rb) for *_, rb in pairs if rb.failed)),
            "per_family": per_family}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--loop", required=True)
    parser.add_argument("--a", required=True, help="a sweep folder or loop:after / loop:control / loop:before")
    parser.add_argument("--b", required=True, help="a sweep folder or loop:after / loop:control / loop:before")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = pair_arms(Path(args.loop), args.a, args.b)
    if args.json:
        print(json.dumps(result))
        return
    print(f"{args.loop}: A = {args.a}, B = {args.b}; {result['pairs']} pairs "
          f"({result['missing']} missing, {result['errors']} errored)")
    print(f"A failed {result['a_failed']}, B failed {result['b_failed']}; A only {result['a_only']}, "
          f"B only {result['b_only']}, both {result['both_fail']}, neither {result['neither']}; "
          f"exact McNemar p = {result['mcnemar_p']:.3g}")
    print(f"failure kinds A {result['kinds_a']}, B {result['kinds_b']}")
    for fam, row in result["per_family"].items():
        print(f"  {fam}: {row['pairs']} pairs, A {row['a_failed']}, B {row['b_failed']} "
              f"(A only {row['a_only']}, B only {row['b_only']}), p = {row['mcnemar_p']:.3g}")


if __name__ == "__main__":
    main()
