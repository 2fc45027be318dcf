"""Which policy a ``dv2s loop`` run recommends, and why: its verdict and exit status.

A round's fine-tuned policy is *accepted* when three tests say so: the regression test on the rest of the
starting bank (``dv2s regress``'s paired non-inferiority test against the policy the round started from)
PASSed, and on the held-out families it is significantly worse neither than the policy it started from nor
than the control arm (the same fine-tuning without the mined scenarios). "Significantly worse" is
``dv2s regress``'s gate on the held-out pairs (:func:`heldout_worse`): one-sided exact McNemar tests per
held-out family and pooled, family-wise level :data:`HELDOUT_ALPHA` (:func:`dv2s_gym.regress.stats.compare_scenarios`
with no margin), so a harm confined to one family is not averaged away. It is *rejected* when the regression test
FAILed or either held-out test found it worse; it is *not accepted* when the regression test is INCONCLUSIVE or
in ERROR, when the round skipped, or when the held-out tests did not run (too few held-out episodes or families:
no test, no acceptance; never fewer than :data:`EVIDENCE_FLOOR` tested pairs and one family, below which no exact
McNemar test can be significant). It is not accepted either when a harm confined to one held-out family is not ruled
out (:func:`family_harm`, the rule a regulator applies to subgroups): a held-out family whose point estimate (the
fine-tuned policy's failure rate minus the start's, or the control's, on its paired episodes) is worse for the
fine-tuned policy by more than the loop's margin blocks ACCEPTED, even when the significance gate calls it
inconclusive. The point estimate alone decides. Beside it each family's one-sided non-inferiority test at the margin
(Newcombe's paired interval, Holm-adjusted over the families) is reported as evidence and decides nothing: a family
worse than the margin can never show non-inferiority, and a family within the margin that does not show it (too few
pairs to tell) does not block. Without a control arm only the test against the start is required. Each round is
tested against the policy it started from, so with two or more tested rounds a fine-tuned policy that FAILs
against the starting one (``final_vs_start``) is rejected too, and is not accepted when that comparison
cannot run; when that comparison is INCONCLUSIVE the reason says so. A fine-tuned policy that FAILs against the
starting policy on the untouched scenario set (never mined, never fine-tuned on) is not accepted either. The verdict's
reason names the test that decided
it. The recommended policy (the policy to use) is the last accepted one, else the starting policy; every
round's policy meets the cross-round check over the rounds up to it, and one that check rejected sends the
recommendation back to the starting policy, so it is never the policy to use.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Dict, Mapping, Optional, Union

from dv2s_gym.loop.record import (FamilyHarm, FamilyHarmRow, FinalVsStart, HeldOutComparison, HeldOutWorse,
                                  LoopReportBody, RecordedLoopSettings, RegressComparison, RegressSummary, RoundRecord,
                                  RoundSteps, recorded)
from dv2s_gym.loop.settings import DEFAULTS, EVIDENCE, LoopError

if TYPE_CHECKING:  # the regression statistics load scipy, kept off the command line's start: imported where used
    from dv2s_gym.regress.stats import PairedTable

__all__ = ["ACCEPTED", "REJECTED", "NOT_ACCEPTED", "EXIT_CODES", "CONTROL_ALPHA", "HELDOUT_ALPHA", "HELDOUT_TEST",
           "FAMILY_RULE", "family_harm", "non_inferiority_p",
           "EVIDENCE_HINT", "evidence_hint", "EVIDENCE_FLOOR", "fewest_significant_pairs", "evidence_floor_note", "judge_round",
           "heldout_worse", "too_small", "Judgement", "Recommendation", "recommendation"]

ACCEPTED, REJECTED, NOT_ACCEPTED = "ACCEPTED", "REJECTED", "NOT ACCEPTED"
EXIT_CODES = {ACCEPTED: 0, REJECTED: 1, NOT_ACCEPTED: 3}
"""``dv2s loop``'s exit status for the verdict on the last round's fine-tuned policy."""
HELDOUT_ALPHA = 0.05
"""Family-wise level of the held-out tests: is the fine-tuned policy significantly worse than the start, or than
the control, on the held-out families (:func:`heldout_worse`)."""
CONTROL_ALPHA = HELDOUT_ALPHA
"""The level of the held-out test against the control (the same as :data:`HELDOUT_ALPHA`)."""
HELDOUT_TEST = (f"one-sided exact McNemar tests per held-out family and pooled, family-wise level {HELDOUT_ALPHA:g} "
                "(the dv2s regress gate)")
"""The held-out tests in words, as the verdict's reason and the reports name them."""


def fewest_significant_pairs(alpha: float = HELDOUT_ALPHA) -> int:
    """The fewest paired episodes with which the exact McNemar test can reach ``p < alpha`` at all: ``m`` discordant
    pairs, all one way, give a two-sided p of ``2 * 0.5 ** m`` (so 6 at 0.05), and there are never more discordant
    pairs than pairs. The held-out gate's pooled one-sided test, which starts at half the level, needs as many."""
    m = 1
    while min(1.0, 2.0 * 0.5 ** m) >= alpha:
        m += 1
    return m


EVIDENCE_FLOOR = fewest_significant_pairs()
"""The fewest tested held-out pairs (no error on either side) a round needs before its held-out tests count, and so
before its fine-tuned policy can be ACCEPTED or REJECTED on them, whatever ``--min-heldout-episodes`` says: below it
no held-out test can ever reach significance, so a harm could never be found. A round also needs at least one family
with a tested pair (each family it counts has one)."""


def evidence_floor_note(min_episodes: int, min_families: int) -> Optional[str]:
    """The warning for held-out minimums below what can ever give evidence (:data:`EVIDENCE_FLOOR` pairs, one
    family), or ``None``."""
    low = []
    if min_episodes < EVIDENCE_FLOOR:
        low.append(f"--min-heldout-episodes {min_episodes} is below {EVIDENCE_FLOOR}: with fewer than "
                   f"{EVIDENCE_FLOOR} discordant pairs the exact McNemar test cannot reach p < {HELDOUT_ALPHA:g}, so "
                   "no held-out test could ever show a harm")
    if min_families < 1:
        low.append(f"--min-heldout-families {min_families} counts no family: a test needs at least one family with "
                   "a tested pair")
    if not low:
        return None
    return ("; ".join(low) + f"; the loop judges no round on fewer than {EVIDENCE_FLOOR} tested held-out pairs or on "
            "no family with a tested pair (such a round is TOO SMALL TO JUDGE)")


EVIDENCE_HINT = "run `dv2s loop --profile evidence` for a round large enough to judge"
"""What a round too small to judge its policy tells the user to do (the profile of
:data:`dv2s_gym.loop.settings.EVIDENCE`), unless it already ran at that profile's sizes (:func:`evidence_hint`)."""

_SIZES = ("budget", "k_eval", "regress_episodes")
"""The settings that make a round large enough to judge, as the evidence profile sets them."""


def evidence_hint(settings: Optional[RecordedLoopSettings]) -> str:
    """What to run for a round large enough to judge: the evidence profile, or, for a round that already had its
    sizes (mining budget, held-out seeds, regression seeds per scenario), larger ones than the profile's."""
    values = dict(settings.extra) if settings is not None else {}
    sizes = {name: values.get(name) for name in _SIZES}
    if any(not isinstance(value, int) or value < EVIDENCE[name] for name, value in sizes.items()):
        return EVIDENCE_HINT
    return (f"this round already ran at the evidence profile's sizes; raise --k-eval (now {sizes['k_eval']}) and "
            f"--regress-episodes (now {sizes['regress_episodes']}) for a round large enough to judge")


def too_small(record: RoundRecord) -> Optional[str]:
    """Why round ``record`` (a :class:`~dv2s_gym.loop.record.RoundRecord`; its JSON object is read with
    ``RoundRecord.from_dict``) was too small to judge its fine-tuned policy, or ``None``: too few held-out episodes
    or families for a drop or a test, or a regression test that could not tell."""
    steps = RoundRecord.from_dict(record).steps
    reasons = []
    after = steps.after if steps.after is not None else HeldOutComparison()
    if after.underpowered:
        reasons.append("too few held-out episodes or families for a drop or a test")
    elif _control_below_floor(after):
        reasons.append("too few held-out episodes or families for the test against the control")
    regress = steps.regress if steps.regress is not None else RegressSummary()
    if regress.verdict == "INCONCLUSIVE":
        reasons.append(f"the regression test on {regress.episodes} paired episodes could not tell")
    return "; ".join(reasons) or None


FAMILY_RULE = ("per held-out family, a point estimate (the fine-tuned policy's failure rate minus the other's on the "
               "family's paired episodes) worse for the fine-tuned policy by more than the margin blocks ACCEPTED; "
               "reported beside it as evidence, deciding nothing: the family's one-sided non-inferiority test at the "
               "margin (Newcombe's paired interval), Holm-adjusted over the families at one-sided "
               f"{HELDOUT_ALPHA / 2:g}, which a family worse than the margin can never pass")
"""The held-out families' harm rule in words (:func:`family_harm`), as the verdict's reason and the reports name it:
the point estimate against the margin decides; the Holm-adjusted non-inferiority test is evidence only."""


def non_inferiority_p(table: Any, margin: float) -> float:
    """One-sided p-value of ``H0: the candidate's failure rate exceeds the baseline's by at least margin`` on a paired
    table: the smallest one-sided level ``a`` at which the upper end of the two-sided ``1 - 2a`` Newcombe interval of
    the difference (:func:`dv2s_gym.regress.stats.paired_difference_interval`) is below ``margin`` (so ``p < 0.025``
    exactly when the 95 % interval's upper end is below it, ``dv2s regress``'s PASS); 1.0 when the point estimate
    reaches the margin (an interval always contains its estimate) or the table is empty."""
    from dv2s_gym.regress.stats import paired_difference_interval

    if not table.n or table.difference >= margin:
        return 1.0

    def shown(level: float) -> bool:
        return paired_difference_interval(table, 1.0 - 2.0 * level)[1] < margin

    low, high = 1e-12, 0.5 - 1e-9
    if shown(low):
        return 0.0
    if not shown(high):
        return 1.0
    for _ in range(60):
        middle = (low + high) / 2.0
        low, high = (low, middle) if shown(middle) else (middle, high)
    return high


def family_harm(tables: Mapping[str, "PairedTable"], margin: float) -> FamilyHarm:
    """The held-out families' harm rule (:data:`FAMILY_RULE`) on ``{family: PairedTable}`` of the fine-tuned policy
    (candidate) against another (baseline): per family the difference in failure rate (the point estimate) with its
    two-sided 95 % Newcombe interval, ``harm``: that difference worse for the fine-tuned policy by more than
    ``margin`` (this alone decides), and as evidence beside it the one-sided non-inferiority p-value at ``margin``
    (:func:`non_inferiority_p`), its Holm adjustment over the families and ``non_inferior`` (shown: adjusted p below
    :data:`HELDOUT_ALPHA` / 2). A harmed family is never non-inferior (its p-value is 1), so the test cannot clear
    it; a family within the margin that is not shown non-inferior is not harmed. Returns a
    :class:`~dv2s_gym.loop.record.FamilyHarm`: the ``margin``, the ``rule``, each family's row, the ``harmed``
    families and those shown ``non_inferior``."""
    from dv2s_gym.regress.stats import holm, paired_difference_interval

    names = [name for name in sorted(tables) if tables[name].n]
    raw = [non_inferiority_p(tables[name], margin) for name in names]
    adjusted = holm(raw)
    families: Dict[str, FamilyHarmRow] = {}
    for name, p, q in zip(names, raw, adjusted):
        t = tables[name]
        low, high = paired_difference_interval(t, 1.0 - HELDOUT_ALPHA)
        families[name] = FamilyHarmRow(pairs=t.n, fine_tuned_only=t.candidate_only, other_only=t.baseline_only,
                                       difference=t.difference, interval=(low, high), non_inferiority_p=p, holm_p=q,
                                       non_inferior=q < HELDOUT_ALPHA / 2.0, harm=t.difference > margin)
    return FamilyHarm(margin=margin, rule=FAMILY_RULE, families=families,
                      harmed=tuple(name for name in names if families[name].harm),
                      non_inferior=tuple(name for name in names if families[name].non_inferior))


def _harm_text(harm: FamilyHarm, label: str) -> str:
    """The harmed families of :func:`family_harm`, in words."""
    parts = []
    for name in harm.harmed:
        f = harm.families[name]
        parts.append(f"in family {name} the fine-tuned policy failed {f.fine_tuned_only} of {f.pairs} pairs "
                     f"that {label} passed and passed {f.other_only} it failed ({100 * f.difference:+.1f} pp, "
                     f"95% CI {100 * f.interval[0]:+.1f} to {100 * f.interval[1]:+.1f} pp, worse than the "
                     f"margin {100 * harm.margin:+.1f} pp, so non-inferiority cannot be shown: Holm-adjusted "
                     f"one-sided p = {f.holm_p:.3g})")
    return "; ".join(parts)


def heldout_worse(tables: Mapping[str, Union["PairedTable", Mapping[str, int]]], against: str,
                  margin: Optional[float] = None) -> Optional[HeldOutWorse]:
    """Whether the fine-tuned policy is significantly worse than ``against`` (``"start"`` or ``"control"``) on
    the held-out families: ``tables`` maps each held-out family to its paired table of fine-tuned (candidate)
    against ``against`` (baseline), a :class:`~dv2s_gym.regress.stats.PairedTable` or its dict
    (``both_fail``, ``candidate_only``, ``baseline_only``, ``neither``). ``dv2s regress``'s gate decides
    (:func:`dv2s_gym.regress.stats.compare_scenarios` with no margin, family-wise level :data:`HELDOUT_ALPHA`):
    worse when a family's or the pooled one-sided exact McNemar test rejects "no worse" with the fine-tuned policy
    failing more. Returns a :class:`~dv2s_gym.loop.record.HeldOutWorse` (``against``, ``test``, ``worse``, the
    numbers of ``families`` and ``pairs``, ``fine_tuned_only``, ``other_only``, ``p_value`` (pooled, unadjusted),
    ``worse_families``, ``reason``, ``family_harm``), or ``None`` without pairs; ``family_harm`` is :func:`family_harm` of the same tables at ``margin`` (default: the loop's default
    margin)."""
    from dv2s_gym.regress.stats import PairedTable, Verdict, compare_scenarios

    tables = {str(name): t if isinstance(t, PairedTable) else PairedTable(**dict(t)) for name, t in tables.items()}
    tables = {name: t for name, t in sorted(tables.items()) if t.n}
    if not tables:
        return None
    per, overall = compare_scenarios(tables, margin=0.0, alpha=HELDOUT_ALPHA)
    pooled = PairedTable.pooled(list(tables.values()))
    failed = [name for name, comparison in per.items() if comparison.verdict is Verdict.FAIL]
    worse = overall.verdict is Verdict.FAIL
    label = "the starting policy" if against == "start" else "the control"
    where = (f" (in famil{'y' if len(failed) == 1 else 'ies'} {', '.join(failed)})" if failed else "")
    reason = (f"{pooled.n} held-out pairs from {len(tables)} famil{'y' if len(tables) == 1 else 'ies'}: only the "
              f"fine-tuned policy failed {pooled.candidate_only}, only {label} {pooled.baseline_only}; pooled "
              f"one-sided p = {overall.p_value:.3g}; "
              + (f"significantly worse{where}" if worse else "not significantly worse"))
    return HeldOutWorse(against=against, test=HELDOUT_TEST, worse=worse, families=len(tables), pairs=pooled.n,
                        fine_tuned_only=pooled.candidate_only, other_only=pooled.baseline_only,
                        p_value=overall.p_value, worse_families=tuple(failed), reason=reason,
                        family_harm=family_harm(tables, _default_margin() if margin is None else float(margin)))


def _default_margin() -> float:
    return float(DEFAULTS["margin"])


def _heldout_tests(after: HeldOutComparison) -> Dict[str, Optional[HeldOutWorse]]:
    """The held-out tests of a round's ``after`` step as recorded (``significantly_worse``); ``None`` where none
    ran (none does below the minimums or :data:`EVIDENCE_FLOOR`)."""
    return {"start": after.held_out_test("start"), "control": after.held_out_test("control")}


def _control_below_floor(after: HeldOutComparison) -> Optional[str]:
    """Why the held-out test against the control did not run (``vs_control``'s ``underpowered``: too few tested
    pairs or families against the control); ``None`` when it ran or there is no control."""
    versus = after.vs_control
    return str(versus.underpowered) if versus is not None and versus.underpowered else None


@dataclasses.dataclass(frozen=True)
class Judgement:
    """The verdict on one round's fine-tuned policy (:func:`judge_round`)."""

    verdict: str
    """ACCEPTED, REJECTED or NOT ACCEPTED."""
    decided_by: str
    """The test that decided (``regression``, ``heldout_vs_control``, ``heldout_vs_start``,
    ``heldout_families_vs_start`` / ``_vs_control``, ``untouched``, ``final_vs_start``, ``all`` when every test
    agreed on ACCEPTED), or the missing one."""
    reason: str
    """Why, in words."""


def judge_round(record: RoundRecord) -> Optional[Judgement]:
    """The verdict on round ``record``'s fine-tuned policy (module docstring; a
    :class:`~dv2s_gym.loop.record.RoundRecord`, its JSON object read with ``RoundRecord.from_dict``), a
    :class:`Judgement`; ``None`` when the round fine-tuned none."""
    record = RoundRecord.from_dict(record)
    found = _judged(record)
    if found is None:
        return None
    # a vacuous untouched set is named whatever decided: a reader must not take its silence for a pass
    untouched = record.steps.untouched
    vacuous = untouched.vacuous() if untouched is not None else None
    if vacuous:
        found["reason"] += f"; on the untouched set {vacuous}"
    return Judgement(**found)


def _judged(record: RoundRecord) -> Optional[Dict[str, str]]:
    """:func:`judge_round`'s verdict, reason and deciding test as keyword arguments of :class:`Judgement`."""
    steps = record.steps
    if not record.fine_tuned:
        return None
    tested = recorded(steps.regress)  # a regression step with something recorded
    regress = steps.regress if steps.regress is not None else RegressSummary()
    verdict = regress.verdict
    after = steps.after if steps.after is not None else HeldOutComparison()
    tests = _heldout_tests(after)
    regression = "the regression test on the rest of the bank (paired non-inferiority against the round's start)"
    if verdict == "FAIL":
        return {"verdict": REJECTED, "decided_by": "regression",
                "reason": f"the fine-tuned policy regressed on the rest of the bank: {regression} FAILed "
                          f"({regress.reason})"}
    for key, label in (("control", "the control (the same fine-tuning without the mined scenarios)"),
                       ("start", "the starting policy")):
        test = tests.get(key)
        if test is not None and test.worse:
            return {"verdict": REJECTED, "decided_by": f"heldout_vs_{key}",
                    "reason": f"the fine-tuned policy is significantly worse than {label} on the held-out families "
                              f"({test.test}: {test.reason})"}
    if not tested:
        return {"verdict": NOT_ACCEPTED, "decided_by": "regression", "reason": "the round has no regression test yet"}
    if verdict != "PASS":
        return {"verdict": NOT_ACCEPTED, "decided_by": "regression",
                "reason": f"{regression} is {verdict}, so no regression is ruled out ({regress.reason})"}
    missing = [key for key in ("start", "control") if tests.get(key) is None
               and (key == "start" or recorded(after.control) or after.vs_control is not None)]
    if missing:
        why = (after.underpowered or (_control_below_floor(after) if missing == ["control"] else None)
               or ("no held-out pair ran" if not after.pairs else "not recorded"))
        return {"verdict": NOT_ACCEPTED, "decided_by": f"heldout_vs_{missing[0]}",
                "reason": f"{regression} PASSed, but the held-out test against "
                          f"{' and '.join('the starting policy' if k == 'start' else 'the control' for k in missing)}"
                          f" did not run ({why}), so a harm on the held-out families is not ruled out"}
    for key, label in (("start", "the starting policy"), ("control", "the control")):
        test = tests.get(key)
        if test is None:
            continue
        harm = test.family_harm if test.family_harm is not None else FamilyHarm()
        if harm.harmed:
            return {"verdict": NOT_ACCEPTED, "decided_by": f"heldout_families_vs_{key}",
                    "reason": f"{regression} PASSed and the fine-tuned policy is not significantly worse than "
                              f"{label} on the held-out families, but a harm there is not ruled out: "
                              f"{_harm_text(harm, label)} ({FAMILY_RULE})"}
    untouched = _untouched_fail(steps)
    if untouched:
        return {"verdict": NOT_ACCEPTED, "decided_by": "untouched",
                "reason": f"{regression} PASSed and the held-out tests found no harm, but {untouched}"}
    parts = [f"not significantly worse than {'the starting policy' if key == 'start' else 'the control'} "
             f"(p = {test.p_value:.3g} on {test.pairs} held-out pairs from "
             f"{test.families} famil{'y' if test.families == 1 else 'ies'})"
             for key in ("start", "control") for test in [tests.get(key)] if test is not None]
    control_note = "" if tests.get("control") is not None else "; no control arm to compare with"
    margin = tests["start"].family_harm.margin  # the test against the start always ran here (else missing)
    control_note += (f"; no held-out family worse for the fine-tuned policy by more than the margin "
                     f"{100 * margin:+.1f} pp ({FAMILY_RULE})")
    return {"verdict": ACCEPTED, "decided_by": "all",
            "reason": f"no regression on the rest of the bank ({regression} PASSed: {regress.reason}); on "
                      f"the held-out families {' and '.join(parts)} ({HELDOUT_TEST}){control_note}"}


def _untouched_fail(steps: RoundSteps) -> Optional[str]:
    """Why the untouched scenario set blocks ACCEPTED (the fine-tuned policy FAILed against the start there:
    significantly worse), or ``None``."""
    versus = steps.untouched.fine_tuned_vs_start if steps.untouched is not None else None
    versus = versus if versus is not None else RegressComparison()
    if versus.verdict != "FAIL":
        return None
    return (f"on the untouched scenario set (never mined or fine-tuned on) the fine-tuned policy FAILed against the "
            f"starting policy ({versus.reason}), so it harms scenes the loop did not touch")


def _with_cross_round_check(judged: Judgement, final: Optional[FinalVsStart]) -> Judgement:
    """``judged`` (an ACCEPTED round's verdict) after the cross-round check on its policy (``final_vs_start`` over
    the rounds up to it): REJECTED when that check FAILed, NOT ACCEPTED when it could not run (an error):
    a check that cannot run never counts as passed."""
    if judged.verdict != ACCEPTED or final is None:
        return judged
    rounds = ", ".join(map(str, final.rounds or ()))
    if final.error:
        return Judgement(verdict=NOT_ACCEPTED, decided_by="final_vs_start",
                         reason=f"the regression test of the fine-tuned against the starting policy on the starting "
                                f"bank, over the rounds so far, could not run ({final.error}), so a regression "
                                f"against the starting policy is not ruled out")
    if final.verdict == "FAIL":  # each round passed against its own start
        return Judgement(verdict=REJECTED, decided_by="final_vs_start",
                         reason=f"over rounds {rounds} the fine-tuned policy regressed against the starting one on "
                                f"the starting bank: the regression test of the fine-tuned against the starting "
                                f"policy FAILed ({final.reason})")
    if final.verdict == "INCONCLUSIVE":
        return dataclasses.replace(judged, reason=f"{judged.reason}; but over rounds {rounds} the regression test of "
                                                  f"the fine-tuned against the starting policy on the starting bank "
                                                  f"was INCONCLUSIVE ({final.reason}): no regression against the "
                                                  "starting policy over the rounds is shown, nor ruled out")
    return judged


@dataclasses.dataclass(frozen=True)
class Recommendation:
    """Which policy a loop recommends and why (:func:`recommendation`); ``report.json``'s ``recommendation`` is its
    :meth:`to_dict`."""

    policy: Optional[str]
    """The spec of the policy to use."""
    verdict: str
    """The verdict on the last fine-tuned policy: ACCEPTED, REJECTED or NOT ACCEPTED."""
    round: Optional[int]
    """The number of the round that fine-tuned it (``None``: no round fine-tuned a policy)."""
    candidate: Optional[str]
    """That policy's spec."""
    reason: str
    """Why, naming the test that decided."""
    decided_by: Optional[str]
    """The test that decided (:func:`judge_round`; ``final_vs_start`` for the comparison over the rounds)."""
    exit_code: int
    """``dv2s loop``'s exit status (:data:`EXIT_CODES`)."""
    too_small: Optional[str]
    """Why a NOT ACCEPTED round was too small to judge (:func:`too_small`; the sentence then points to the evidence
    profile), or ``None``."""
    sentence: str
    """The verdict in one line for people."""

    def to_dict(self) -> Dict[str, Any]:
        """The JSON object ``report.json`` holds (every field, ``null`` included)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Any, source: str = "the loop report") -> "Recommendation":
        """The recommendation of a JSON object :meth:`to_dict` wrote; :class:`LoopError` names ``source`` (the file
        or report it was read from) when there is none or a field is missing."""
        if isinstance(data, cls):
            return data
        names = [field.name for field in dataclasses.fields(cls)]
        if not isinstance(data, Mapping):
            raise LoopError(f"{source} holds no recommendation; it is written with every loop report: rerun the "
                            "loop in its folder to write the report again")
        missing = [name for name in names if name not in data]
        if missing:
            raise LoopError(f"{source}'s recommendation has no {', '.join(missing)}; rerun the loop in its folder "
                            "to write the report again")
        return cls(**{name: data[name] for name in names})


def recommendation(report: LoopReportBody) -> Recommendation:
    """The loop's recommendation from its report (``report.json``'s body): the policy to use, the verdict on the
    last fine-tuned policy and why (:class:`Recommendation`)."""
    start = report.start_policy
    rounds = list(report.round_records)
    judged_rounds = [(record, judged) for record in rounds for judged in [judge_round(record)] if judged is not None]
    if not judged_rounds:
        return Recommendation(policy=start, verdict=NOT_ACCEPTED, round=None, candidate=None,
                              reason="no round fine-tuned a policy", decided_by=None,
                              exit_code=EXIT_CODES[NOT_ACCEPTED], too_small=None,
                              sentence=f"NOT ACCEPTED: no round fine-tuned a policy; keep the starting policy {start}")
    recommended = start
    for index, (record, judged) in enumerate(judged_rounds):
        # the cross-round check on this round's policy: the report's own for the last round, else the one
        # recorded with the round (the check over the rounds up to it)
        final = (report.final_vs_start if index == len(judged_rounds) - 1 and report.cross_round_checked
                 else record.final_vs_start)
        judged = _with_cross_round_check(judged, final)
        judged_rounds[index] = (record, judged)
        if judged.verdict == ACCEPTED:
            recommended = record.new_policy or report.policy
        elif judged.decided_by == "final_vs_start" and judged.verdict == REJECTED:
            recommended = start  # the lineage regressed against the starting policy: back to it
    record, judged = judged_rounds[-1]
    candidate = record.new_policy or report.policy
    number = record.round
    if judged.verdict == ACCEPTED:
        sentence = f"ACCEPTED: use the round {number} fine-tuned policy {candidate}: {judged.reason}"
    else:
        keep = "the starting policy" if recommended == start else "the last accepted policy"
        sentence = (f"{judged.verdict}: keep {keep} {recommended}, not the round {number} fine-tuned policy "
                    f"{candidate}: {judged.reason}")
    small = too_small(record) if judged.verdict == NOT_ACCEPTED else None
    if small:
        sentence += f". TOO SMALL TO JUDGE ({small}): {evidence_hint(report.settings)}"
    return Recommendation(policy=recommended, verdict=judged.verdict, round=number, candidate=candidate,
                          reason=judged.reason, decided_by=judged.decided_by,
                          exit_code=EXIT_CODES[judged.verdict], too_small=small, sentence=sentence)
