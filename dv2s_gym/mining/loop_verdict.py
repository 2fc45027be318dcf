"""Which policy a ``dv2s loop`` run recommends, and why: its verdict and exit status.

A round's fine-tuned policy is *accepted* when the regression test on the rest of the starting bank
PASSed and the control arm (the same fine-tuning without the mined scenarios) did not beat it on the
held-out episodes (exact McNemar p below :data:`CONTROL_ALPHA`, the control failing fewer). It is
*rejected* when the regression test FAILed or the control beat it; any other outcome (INCONCLUSIVE or
ERROR regression test, a skipped round) leaves it *not accepted*. Each round is tested against the policy it
started from, so with two or more tested rounds a final policy that FAILs against the starting one
(``final_vs_start``) is rejected too. The recommended policy is the last accepted one, else the starting
policy.
"""

from __future__ import annotations

from typing import Any, Dict, Mapping, Optional

__all__ = ["ACCEPTED", "REJECTED", "NOT_ACCEPTED", "EXIT_CODES", "CONTROL_ALPHA", "EVIDENCE_HINT", "judge_round",
           "too_small", "recommendation"]

ACCEPTED, REJECTED, NOT_ACCEPTED = "ACCEPTED", "REJECTED", "NOT ACCEPTED"
EXIT_CODES = {ACCEPTED: 0, REJECTED: 1, NOT_ACCEPTED: 3}
"""``dv2s loop``'s exit status for the verdict on the last round's fine-tuned policy."""
CONTROL_ALPHA = 0.05
"""Below this McNemar p, a control failing fewer held-out episodes than the fine-tuned policy beats it."""


EVIDENCE_HINT = "run `dv2s loop --profile evidence` for a round large enough to judge"
"""What a round too small to judge its policy tells the user to do (the profile of
:data:`dv2s_gym.mining.loop_settings.EVIDENCE`)."""


def too_small(record: Mapping[str, Any]) -> Optional[str]:
    """Why round ``record`` was too small to judge its fine-tuned policy, or ``None``: too few held-out episodes
    or families for a drop or a test, or a regression test that could not tell."""
    steps = record.get("steps") or {}
    reasons = []
    if (steps.get("after") or {}).get("underpowered"):
        reasons.append("too few held-out episodes or families for a drop or a test")
    if (steps.get("regress") or {}).get("verdict") == "INCONCLUSIVE":
        reasons.append(f"the regression test on {(steps.get('regress') or {}).get('episodes')} paired episodes "
                       "could not tell")
    return "; ".join(reasons) or None


def judge_round(record: Mapping[str, Any]) -> Optional[Dict[str, str]]:
    """``{"verdict", "reason"}`` on round ``record``'s fine-tuned policy; ``None`` when the round fine-tuned none."""
    steps = record.get("steps") or {}
    if not record.get("new_policy") and "fine_tune" not in steps:
        return None
    regress = steps.get("regress") or {}
    verdict = regress.get("verdict")
    versus = (steps.get("after") or {}).get("vs_control") or {}
    table, p = versus.get("table") or {}, versus.get("mcnemar_p")
    if verdict == "FAIL":
        return {"verdict": REJECTED, "reason": f"the fine-tuned policy regressed on the rest of the bank "
                                               f"({regress.get('reason')})"}
    if p is not None and p < CONTROL_ALPHA and table.get("fine_tuned_only", 0) > table.get("control_only", 0):
        return {"verdict": REJECTED, "reason": f"the control (the same fine-tuning without the mined scenarios) "
                                               f"failed fewer held-out episodes (McNemar p = {p:.3g})"}
    if verdict == "PASS":
        return {"verdict": ACCEPTED, "reason": f"no regression on the rest of the bank ({regress.get('reason')})"
                + ("" if p is not None or not versus else "; the held-out comparison with the control was not tested")}
    if not regress:
        return {"verdict": NOT_ACCEPTED, "reason": "the round has no regression test yet"}
    return {"verdict": NOT_ACCEPTED, "reason": f"the regression test on the rest of the bank is {verdict}, so "
                                               f"no regression is ruled out ({regress.get('reason')})"}


def recommendation(report: Mapping[str, Any]) -> Dict[str, Any]:
    """The loop's recommendation from its report (``report.json``'s body).

    Returns ``{"policy": the recommended spec, "verdict": the last fine-tuned policy's (ACCEPTED, REJECTED,
    NOT ACCEPTED), "round", "candidate": that policy's spec, "reason", "sentence": one line for people,
    "exit_code", "too_small": why a NOT ACCEPTED round was too small to judge (:func:`too_small`; the sentence
    then points to the evidence profile) or ``None``}``."""
    start = (report.get("settings") or {}).get("policy")
    recommended, last = start, None
    for record in report.get("rounds") or []:
        judged = judge_round(record)
        if judged is None:
            continue
        last = (record, judged)
        if judged["verdict"] == ACCEPTED:
            recommended = record.get("new_policy") or report.get("policy")
    if last is None:
        return {"policy": start, "verdict": NOT_ACCEPTED, "round": None, "candidate": None,
                "reason": "no round fine-tuned a policy", "exit_code": EXIT_CODES[NOT_ACCEPTED], "too_small": None,
                "sentence": f"NOT ACCEPTED: no round fine-tuned a policy; keep the starting policy {start}"}
    record, judged = last
    candidate = record.get("new_policy") or report.get("policy")
    number = record.get("round")
    final = report.get("final_vs_start") or {}
    if judged["verdict"] == ACCEPTED and final.get("verdict") == "FAIL":  # each round passed against its own start
        judged = {"verdict": REJECTED, "reason": f"over rounds {', '.join(map(str, final.get('rounds') or []))} "
                                                 f"the fine-tuned policy regressed against the starting one on the "
                                                 f"starting "
                                                 f"bank ({final.get('reason')})"}
        recommended = start
    if judged["verdict"] == ACCEPTED:
        sentence = f"ACCEPTED: use the round {number} fine-tuned policy {candidate}: {judged['reason']}"
    else:
        keep = "the starting policy" if recommended == start else "the last accepted policy"
        sentence = (f"{judged['verdict']}: keep {keep} {recommended}, not the round {number} fine-tuned policy "
                    f"{candidate}: {judged['reason']}")
    small = too_small(record) if judged["verdict"] == NOT_ACCEPTED else None
    if small:
        sentence += f". TOO SMALL TO JUDGE ({small}): {EVIDENCE_HINT}"
    return {"policy": recommended, "verdict": judged["verdict"], "round": number, "candidate": candidate,
            "reason": judged["reason"], "exit_code": EXIT_CODES[judged["verdict"]], "too_small": small,
            "sentence": sentence}
