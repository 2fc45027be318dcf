"""A small ``dv2s-regress`` report made by hand from real episodes, for tests of what reads reports
(the HTML page), independent of the runner. Summaries use plain Wilson intervals; the comparison
numbers are computed simply and stand in for the statistics module's."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Sequence

from dv2s_gym.regress.records import BankInfo, PairedEpisode, PolicyInfo, RegressReport, ReportSettings, SequentialOutcome
from dv2s_gym.regress.report import build_report
from policies.evaluation import make_eval_env, run_episode
from policies.registry import load_policy


def report_from_json(*, bank: dict, settings: dict, candidate: dict, baseline: dict | None, episodes: Sequence[dict],
                     sequential: dict | None = None, **options) -> RegressReport:
    """:func:`~dv2s_gym.regress.report.build_report` on the records of the JSON objects a report holds (the bank,
    settings, policies, paired episodes and sequential outcome, as ``report.json`` writes them)."""
    return build_report(bank=BankInfo.from_dict(bank), settings=ReportSettings.from_dict(settings),
                        candidate=PolicyInfo.from_dict(candidate),
                        baseline=None if baseline is None else PolicyInfo.from_dict(baseline),
                        episodes=[PairedEpisode.from_dict(episode) for episode in episodes],
                        sequential=None if sequential is None else SequentialOutcome.from_dict(sequential), **options)


def wilson(k: int, n: int, z: float = 1.96) -> Dict[str, float]:
    if n == 0:
        return {"value": None, "low": None, "high": None}
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"value": p, "low": max(0.0, centre - half), "high": min(1.0, centre + half)}


def mean_stat(values: Sequence[float]) -> Dict[str, float]:
    values = [v for v in values if v is not None]
    if not values:
        return {"value": None, "low": None, "high": None}
    mean = sum(values) / len(values)
    return {"value": mean, "low": min(values), "high": max(values)}


def summary(results: List[dict]) -> dict:
    n = len(results)
    count = lambda key: sum(bool(r[key]) for r in results)  # noqa: E731
    return {"episodes": n, "collision_rate": wilson(count("collided"), n), "off_road_rate": wilson(count("off_road"), n),
            "failure_rate": wilson(count("failed"), n), "success_rate": wilson(count("success"), n),
            "min_ttc": mean_stat([r["min_ttc"] for r in results]), "mean_speed": mean_stat([r["mean_speed"] for r in results]),
            "return": mean_stat([r["episode_return"] for r in results])}


def comparison(cand: List[dict], base: List[dict], margin: float) -> dict:
    table = {"both_fail": 0, "candidate_only": 0, "baseline_only": 0, "neither": 0}
    for c, b in zip(cand, base):
        key = {(True, True): "both_fail", (True, False): "candidate_only", (False, True): "baseline_only",
               (False, False): "neither"}[(c["failed"], b["failed"])]
        table[key] += 1
    n = len(cand)
    diff = (table["candidate_only"] - table["baseline_only"]) / n
    half = 1.96 * math.sqrt(max(table["candidate_only"] + table["baseline_only"], 1)) / n
    discordant = table["candidate_only"] + table["baseline_only"]
    p = sum(math.comb(discordant, i) for i in range(table["candidate_only"], discordant + 1)) / 2 ** discordant
    if diff - half > margin:
        verdict, reason = "FAIL", f"difference {diff:+.2f} is above the margin {margin:+.2f}"
    elif diff + half < margin:
        verdict, reason = "PASS", f"upper bound {diff + half:+.2f} is below the margin {margin:+.2f}"
    else:
        verdict, reason = "INCONCLUSIVE", f"the interval contains the margin {margin:+.2f}"
    return {"table": table, "difference": {"value": diff, "low": max(-1.0, diff - half), "high": min(1.0, diff + half)},
            "p_value": p, "p_adjusted": min(1.0, p * 2), "verdict": verdict, "reason": reason}


def make_report(out_dir: Path, scenarios: Sequence[str] = ("highway_cut_in_from_left", "highway_lead_vehicle_brakes"),
                seeds: Sequence[int] = range(4), candidate: str = "rule?action_noise=0.3", baseline: str = "rule",
                margin: float = 0.05) -> dict:
    """Run both policies on ``scenarios`` x ``seeds`` (traces under ``out_dir/traces``) and build a report."""
    out_dir = Path(out_dir)
    env = make_eval_env(list(scenarios))
    results = {}
    try:
        for role, spec in (("candidate", candidate), ("baseline", baseline)):
            policy = load_policy(spec)
            policy.bind([env])
            for scenario in scenarios:
                for seed in seeds:
                    result, trace = run_episode(env, policy, scenario, seed)
                    rel = Path("traces") / role / f"{scenario}-{seed}.json.gz"
                    trace.save(out_dir / rel)
                    results[(role, scenario, seed)] = dict(result.to_json(), trace=str(rel))
    finally:
        env.close()
    episodes, per_scenario, regressed, newly = [], {}, [], []
    for scenario in scenarios:
        cand = [results[("candidate", scenario, s)] for s in seeds]
        base = [results[("baseline", scenario, s)] for s in seeds]
        comp = comparison(cand, base, margin)
        per_scenario[scenario] = {"candidate": summary(cand), "baseline": summary(base), "comparison": comp}
        if comp["verdict"] == "FAIL":
            regressed.append(scenario)
        for seed, c, b in zip(seeds, cand, base):
            episode_id = f"{scenario}/{seed}"
            episodes.append({"id": episode_id, "scenario": scenario, "seed": seed, "candidate": c, "baseline": b})
            if c["failed"] and not b["failed"]:
                newly.append(episode_id)
    every_c = [e["candidate"] for e in episodes]
    every_b = [e["baseline"] for e in episodes]
    overall_comp = comparison(every_c, every_b, margin)
    verdicts = [v["comparison"]["verdict"] for v in per_scenario.values()]
    verdict = "FAIL" if "FAIL" in verdicts else "INCONCLUSIVE" if "INCONCLUSIVE" in verdicts else "PASS"
    return {
        "schema": "dv2s-regress", "schema_version": 4, "created": "2026-11-23T00:00:00Z", "dv2s_version": "0.1.0",
        "bank": {"path": "scenario_bank/scenarios", "version": "test", "scenarios": list(scenarios)},
        "settings": {"episodes": len(seeds), "seed": 0, "margin": margin, "alpha": 0.05, "sequential": False, "failure": ["collision", "off_road"],
                     "env_config": None, "backend": "local", "workers": 1},
        "candidate": {"spec": candidate, "card": None}, "baseline": {"spec": baseline, "card": None},
        "episodes": episodes, "scenarios": per_scenario,
        "overall": {"candidate": summary(every_c), "baseline": summary(every_b), "comparison": overall_comp},
        "verdict": verdict, "regressed": regressed, "newly_failing": newly, "errors": [], "stopped_early": False,
    }
