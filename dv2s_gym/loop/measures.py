"""The loop's held-out measurements: which held-out episodes the reference driver passes (:func:`reference_gate`),
when a round has too little evidence to judge (:func:`underpowered`), and the ``after`` step's paired comparison of
the fine-tuned policy with the start and the control (:func:`heldout_comparison`)."""

from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Sequence

from dv2s_gym.loop.heldout import episode_failed, failure_types, paired_summary
from dv2s_gym.loop.record import HeldOutComparison, HeldOutTests, ReferenceGate
from dv2s_gym.loop.settings import DEFAULTS
from dv2s_gym.loop.verdict import EVIDENCE_FLOOR, HELDOUT_ALPHA, heldout_worse
from dv2s_gym.mining.miner import MineSettings
from dv2s_gym.regress.stats import PairedTable
from scenario_bank.records import HeldOutEpisode

__all__ = ["REFERENCE_DRIVER", "reference_gate", "underpowered", "heldout_comparison"]


REFERENCE_DRIVER: str = MineSettings.reference
"""The reference driver of the loop: the miner's avoidability reference (:class:`~dv2s_gym.mining.settings.MineSettings`'
default) and the DAgger teacher (:class:`~policies.dagger_config.DaggerConfig`'s default, the same; read from the
miner's settings so that importing the loop does not load torch). The held-out evaluation keeps only the episodes it
passes (:func:`reference_gate`)."""


def reference_gate(records: Sequence[HeldOutEpisode], families: Mapping[str, str]) -> ReferenceGate:
    """The ``reference`` step's record from the reference driver's held-out ``records``: which held-out episodes
    the loop leaves out because the reference driver did not pass them (it failed, by the miner's monitors, or the
    episode errored, so that nobody knows), counted and named, never dropped silently.

    A policy that imitates the reference cannot be expected to pass a scene the reference itself fails, so such a
    pair measures nothing the fine-tuning can change and only adds noise to the held-out comparison. Returns the
    :class:`~dv2s_gym.loop.record.ReferenceGate` (``excluded``: ``[scenario, seed]`` pairs; ``by_scenario``:
    ``{scenario: {"episodes", "excluded", "failures": {type: n}}}``; ``excluded_families``: the families whose
    every episode is left out)."""
    by_scenario: Dict[str, Dict[str, Any]] = {}
    excluded, failed, errored = [], 0, 0
    kept_families, all_families = set(), set()
    for record in records:
        name, seed = str(record.scenario), int(record.seed)
        row = by_scenario.setdefault(name, {"episodes": 0, "excluded": 0, "failures": {}})
        row["episodes"] += 1
        family = families.get(name, name)
        all_families.add(family)
        outcome = episode_failed(record)
        if outcome is False:
            kept_families.add(family)
            continue
        excluded.append([name, seed])
        row["excluded"] += 1
        if outcome is None:
            errored += 1
            kind = "error"
        else:
            failed += 1
            kind = record.failure.type if record.failure is not None else "failure"
        row["failures"][kind] = row["failures"].get(kind, 0) + 1
    return ReferenceGate(reference=REFERENCE_DRIVER, episodes=len(records), kept=len(records) - len(excluded),
                         excluded=tuple(excluded), failed=failed, errored=errored,
                         by_scenario={name: by_scenario[name] for name in sorted(by_scenario)},
                         excluded_families=tuple(sorted(all_families - kept_families)))


def underpowered(episodes: int, minimum: int, families: Optional[int] = None,
                 min_families: int = 0, tested: bool = False) -> Optional[str]:
    """The warning for a round with fewer than ``minimum`` held-out episodes or fewer than ``min_families``
    held-out families (``families``, when known; ``tested``: families with a tested pair), or ``None``. Whatever the
    minimums, a round needs :data:`~dv2s_gym.loop.verdict.EVIDENCE_FLOOR` episodes (below that no exact
    McNemar test can be significant) and one family."""
    reasons = []
    if episodes < max(minimum, EVIDENCE_FLOOR):
        reasons.append(f"only {episodes} held-out episode(s), fewer than the {minimum} needed "
                       "(--min-heldout-episodes)" if episodes < minimum else
                       f"only {episodes} held-out episode(s), fewer than {EVIDENCE_FLOOR}: below {EVIDENCE_FLOOR} "
                       f"discordant pairs the exact McNemar test cannot reach p < {HELDOUT_ALPHA:g}, so the loop "
                       "judges no round on so few whatever --min-heldout-episodes says")
    if families is not None and families < max(min_families, 1):
        reasons.append(f"only {families} held-out famil{'y' if families == 1 else 'ies'} (parent scenarios)"
                       f"{' with a tested pair' if tested else ''}, fewer "
                       f"than the {max(min_families, 1)} needed: episodes of one family are near-identical scenes, "
                       "not independent trials")
    if not reasons:
        return None
    return ("; ".join(reasons) + ": this round reports held-out rates but no drop and no test; raise --k-eval, "
            "--max-conversions, --max-replays or --budget for more held-out scenarios and families, or run "
            "`dv2s loop --profile evidence`")


def heldout_comparison(before: Sequence[HeldOutEpisode], after: Sequence[HeldOutEpisode],
                       control: Optional[Sequence[HeldOutEpisode]], *, min_episodes: int,
                       seed: int = 0, families: Optional[Mapping[str, str]] = None,
                       min_families: int = 0, margin: Optional[float] = None) -> HeldOutComparison:
    """The ``after`` step (a :class:`~dv2s_gym.loop.record.HeldOutComparison`):
    :func:`~dv2s_gym.loop.heldout.paired_summary` of fine-tuned against start, plus the control's rate and the
    paired fine-tuned-vs-control table and exact McNemar p (``vs_control``), and each policy's failures by type
    (``failure_types``: stalls apart from collisions and the rest).

    ``families`` maps each held-out scenario to its family (default: each scenario its own); ``heldout_scenarios``
    and ``sampled_families`` count those the episodes came from, ``heldout_families`` the families with at least
    one tested pair (no error on either side) against the start and, with a control, against the control too. Below ``min_episodes`` pairs or
    ``min_families`` families the drop, its interval and both p-values are ``None`` and ``underpowered``
    says why (the rates, with their wide intervals, stay). ``significantly_worse`` holds, for ``start`` and
    ``control``, whether the fine-tuned policy is significantly worse on the held-out families
    (:func:`dv2s_gym.loop.verdict.heldout_worse`, the verdict's held-out tests; ``None`` when not tested:
    below the minimums, or no control), each with its held-out families' harm rule at ``margin`` (default: the
    loop's default margin; :func:`dv2s_gym.loop.verdict.family_harm`)."""
    scenarios = sorted({str(r.scenario) for r in before})
    # the drop's interval resamples families, the unit the split holds out (scenarios of one family are not
    # independent); a scenario without a family stands for itself
    summary = paired_summary(before, after, seed=seed,
                             families={name: (families or {}).get(name, name) for name in scenarios}).to_dict()
    summary["min_episodes"] = min_episodes
    summary["heldout_scenarios"] = len(scenarios)
    # a family counts only with a tested pair (no error on either side) in each held-out test: one whose episodes
    # all errored tests nothing, so it never makes a round large enough to judge
    def tested_families(baseline: Sequence[HeldOutEpisode]) -> set:
        return {family for family, table in _family_tables(baseline, after, families).items() if table.n}

    tested = tested_families(before)
    if control is not None:
        tested &= tested_families(control)
    summary["heldout_families"] = len(tested)
    summary["sampled_families"] = len({(families or {}).get(name, name) for name in scenarios})
    summary["min_families"] = min_families
    summary["failure_types"] = {"start": failure_types(before), "fine_tuned": failure_types(after)}
    if control is not None:
        versus = paired_summary(control, after, seed=seed, bootstrap=0)
        summary["control"] = versus.before.to_dict()
        summary["failure_types"]["control"] = failure_types(control)
        summary["vs_control"] = {"pairs": versus.pairs, "errors": versus.errors, "relative_drop": versus.relative_drop,
                                 "table": {"both_fail": versus.table.both_fail,
                                           "fine_tuned_only": versus.table.after_only,
                                           "control_only": versus.table.before_only, "neither": versus.table.neither},
                                 "mcnemar_p": versus.mcnemar_p,
                                 "per_scenario": {name: row["before"] for name, row in versus.per_scenario.items()}}
    shortfall = underpowered(summary["pairs"], min_episodes, summary["heldout_families"], min_families, tested=True)
    if shortfall:
        summary["underpowered"] = shortfall
        summary.update(relative_drop=None, relative_drop_interval=[None, None], mcnemar_p=None)
        if "vs_control" in summary:
            summary["vs_control"].update(relative_drop=None, mcnemar_p=None)
    # the test against the control needs the same evidence on its own pairs: a control that errored on most
    # episodes leaves few tested pairs against it, and a test on those says nothing
    control_shortfall = None if control is None else _control_shortfall(summary["vs_control"]["pairs"], tested,
                                                                        min_episodes, min_families)
    if control_shortfall:
        summary["vs_control"].update(underpowered=control_shortfall, relative_drop=None, mcnemar_p=None)
    # is the fine-tuned policy significantly worse than the start / the control on the held-out families
    # (loop_verdict.heldout_worse: the dv2s regress gate over the families); not tested below the minimums

    margin = DEFAULTS["margin"] if margin is None else float(margin)
    summary["margin"] = margin
    tests = HeldOutTests(
        start=None if shortfall else heldout_worse(_family_tables(before, after, families), "start", margin),
        control=None if shortfall or control_shortfall or control is None else heldout_worse(
            _family_tables(control, after, families), "control", margin))
    return HeldOutComparison.from_dict(summary).replace(significantly_worse=tests)


def _control_shortfall(pairs: int, families: set, min_episodes: int, min_families: int) -> Optional[str]:
    """Why the held-out test against the control does not run (too few tested pairs against the control, or too
    few families with one: :func:`underpowered`'s minimums and evidence floor), or ``None``."""
    shortfall = underpowered(pairs, min_episodes, len(families), min_families, tested=True)
    return None if shortfall is None else "against the control: " + shortfall


def _family_tables(baseline: Sequence[HeldOutEpisode], candidate: Sequence[HeldOutEpisode],
                   families: Optional[Mapping[str, str]]) -> Dict[str, Any]:
    """``{held-out family: PairedTable}`` of ``candidate`` against ``baseline`` records, paired by (scenario, seed);
    a pair with an error on either side is left out."""
    twins = {(r.scenario, int(r.seed)): r for r in candidate}
    outcomes: Dict[str, tuple] = {}
    for record in baseline:
        twin = twins.get((record.scenario, int(record.seed)))
        old, new = episode_failed(record), episode_failed(twin) if twin is not None else None
        if old is None or new is None:
            continue
        family = (families or {}).get(str(record.scenario), str(record.scenario))
        pair = outcomes.setdefault(family, ([], []))
        pair[0].append(new)
        pair[1].append(old)
    return {family: PairedTable.from_outcomes(new, old) for family, (new, old) in sorted(outcomes.items())}
