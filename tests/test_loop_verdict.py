"""Which policy `dv2s loop` recommends after its rounds, and the exit status that says so."""

from __future__ import annotations

import json

import pytest

from dv2s_gym.loop.record import LoopReportBody
from dv2s_gym.loop.verdict import FAMILY_RULE, heldout_worse, recommendation
from loop_helpers import held, written_report


def _round(number, verdict, *, control_only=0, fine_tuned_only=0, p=1.0):
    """A round as the loop records it: the fine-tuned policy failed 2 held-out episodes the start passed and passed
    6 the start failed; against the control it failed ``fine_tuned_only`` the control passed and passed
    ``control_only`` it failed (``p`` ``None``: the test against the control did not run)."""
    start = {"held-out": {"both_fail": 2, "candidate_only": 2, "baseline_only": 6, "neither": 10}}
    control = {"held-out": {"both_fail": 0, "candidate_only": fine_tuned_only, "baseline_only": control_only,
                            "neither": 10}}
    versus = {"table": {"control_only": control_only, "both_fail": 0, "neither": 10, "fine_tuned_only": fine_tuned_only},
              "mcnemar_p": p, **({"underpowered": "too few tested pairs against the control"} if p is None else {})}
    return {"round": number, "policy": f"p{number - 1}", "new_policy": f"ppo:round_{number}/policy/model.zip",
            "steps": {"fine_tune": {}, "regress": {"verdict": verdict, "reason": f"reason {number}"},
                      "after": {"pairs": 20, "mcnemar_p": 0.29, "control": {"k": 5, "n": 20},
                                "table": {"both_fail": 2, "after_only": 2, "before_only": 6, "neither": 10},
                                "vs_control": versus,
                                "significantly_worse": {"start": heldout_worse(start, "start"),
                                                        "control": None if p is None else heldout_worse(control,
                                                                                                        "control")}}}}


def _report(*rounds, **extra) -> LoopReportBody:
    policy = rounds[-1].get("new_policy", "dv2s-ppo")
    return LoopReportBody.from_dict({"settings": {"policy": "dv2s-ppo"}, "policy": policy, "rounds": list(rounds),
                                     **extra})


def test_the_last_accepted_policy_is_recommended_and_a_later_regression_is_not():
    verdict = recommendation(_report(_round(1, "PASS"), _round(2, "FAIL")))
    assert verdict.verdict == "REJECTED" and verdict.exit_code == 1
    assert verdict.policy == "ppo:round_1/policy/model.zip" and verdict.candidate.startswith("ppo:round_2")
    assert "keep the last accepted policy ppo:round_1/policy/model.zip" in verdict.sentence
    assert "regressed on the rest of the bank" in verdict.sentence and "FAILed (reason 2)" in verdict.sentence
    assert verdict.decided_by == "regression"


def test_an_accepted_last_round_is_used():
    verdict = recommendation(_report(_round(1, "FAIL"), _round(2, "PASS")))
    assert verdict.verdict == "ACCEPTED" and verdict.exit_code == 0
    assert verdict.policy == "ppo:round_2/policy/model.zip"
    assert verdict.sentence.startswith("ACCEPTED: use the round 2 fine-tuned policy ppo:round_2/policy/model.zip")


def test_rounds_that_each_pass_but_regress_against_the_start_over_all_rounds_are_rejected():
    final = {"verdict": "FAIL", "rounds": [1, 2], "reason": "fails more often"}
    verdict = recommendation(_report(_round(1, "PASS"), _round(2, "PASS"), final_vs_start=final))
    assert verdict.verdict == "REJECTED" and verdict.policy == "dv2s-ppo"
    assert "over rounds 1, 2 the fine-tuned policy regressed against the starting one" in verdict.reason


def test_a_control_that_fails_significantly_fewer_held_out_episodes_rejects_the_policy():
    beaten = recommendation(_report(_round(1, "PASS", control_only=0, fine_tuned_only=8, p=0.008)))
    assert beaten.verdict == "REJECTED" and "the control" in beaten.reason and beaten.policy == "dv2s-ppo"
    assert beaten.decided_by == "heldout_vs_control" and "one-sided exact McNemar" in beaten.reason
    untested = recommendation(_report(_round(1, "PASS", control_only=0, fine_tuned_only=4, p=None)))
    assert untested.verdict == "NOT ACCEPTED" and "did not run" in untested.reason  # no test, no acceptance


def test_an_inconclusive_test_or_no_fine_tuned_policy_is_not_accepted():
    inconclusive = recommendation(_report(_round(1, "INCONCLUSIVE")))
    assert inconclusive.verdict == "NOT ACCEPTED" and inconclusive.exit_code == 3
    assert inconclusive.policy == "dv2s-ppo" and "keep the starting policy dv2s-ppo" in inconclusive.sentence
    skipped = recommendation(_report({"round": 1, "steps": {"skipped": "nothing kept"}}))
    assert skipped.verdict == "NOT ACCEPTED" and skipped.policy == "dv2s-ppo" and skipped.round is None


def test_loop_help_documents_each_exit_status(capsys):
    import pytest

    from dv2s_gym.cli import main

    with pytest.raises(SystemExit):
        main(["loop", "--help"])
    text = capsys.readouterr().out
    for line in ("  0  ACCEPTED: ", "  1  REJECTED: ", "  3  NOT ACCEPTED: ", "  2  bad input; 130 interrupted"):
        assert line in text


def test_a_round_too_small_to_judge_says_so_and_points_to_the_evidence_profile():
    small = _round(1, "INCONCLUSIVE")
    small["steps"]["after"]["underpowered"] = "only 16 held-out episode(s)"
    verdict = recommendation(_report(small))
    assert verdict.verdict == "NOT ACCEPTED" and "too few held-out episodes" in verdict.too_small
    assert "TOO SMALL TO JUDGE" in verdict.sentence and "dv2s loop --profile evidence" in verdict.sentence
    judged = recommendation(_report(_round(1, "PASS")))
    assert judged.too_small is None and "TOO SMALL" not in judged.sentence
    failed = recommendation(_report(_round(1, "FAIL")))
    assert failed.verdict == "REJECTED" and failed.too_small is None


def test_a_round_already_at_the_evidence_sizes_is_told_to_raise_them_not_to_run_the_evidence_profile():
    small = _round(1, "INCONCLUSIVE")
    sizes = {"budget": 240, "k_eval": 10, "regress_episodes": 4}
    at_evidence = recommendation(_report(small, settings={"policy": "dv2s-ppo", **sizes}))
    assert "TOO SMALL TO JUDGE" in at_evidence.sentence and "--profile evidence" not in at_evidence.sentence
    assert "raise --k-eval (now 10) and --regress-episodes (now 4)" in at_evidence.sentence
    for name in sizes:  # one size below the profile's: the profile is the advice
        below = recommendation(_report(small, settings={"policy": "dv2s-ppo", **sizes, name: sizes[name] - 1}))
        assert "dv2s loop --profile evidence" in below.sentence


# --------------------------------------------------------------------------- the held-out tests, as the loop records them
def _episodes(failing):
    """Held-out records of 4 families x 2 scenarios x 4 seeds; ``failing(family, scenario, seed)`` says which fail."""
    return held([{"scenario": f"f{f}_s{s}", "seed": seed, "failed": bool(failing(f, s, seed)), "error": None}
                 for f in range(4) for s in range(2) for seed in range(4)])


def _judged(before, after, control, regress="PASS", **minimums):
    from dv2s_gym.loop.measures import heldout_comparison

    families = {f"f{f}_s{s}": f"family_{f}" for f in range(4) for s in range(2)}
    summary = heldout_comparison(_episodes(before), _episodes(after), None if control is None else _episodes(control),
                                 min_episodes=minimums.get("min_episodes", 8), families=families,
                                 min_families=minimums.get("min_families", 3))
    record = {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
              "steps": {"fine_tune": {}, "after": summary, "regress": {"verdict": regress, "reason": "stand-in"}}}
    return recommendation(_report(record)), summary


def test_a_fine_tuned_policy_significantly_worse_than_the_start_on_the_held_out_families_is_rejected():
    """The regression test PASSed and the control does worse still, but the fine-tuned policy fails 12 held-out
    episodes the starting policy passed (and passes none it failed): not accepted on non-inferiority alone."""
    verdict, summary = _judged(before=lambda f, s, seed: False, after=lambda f, s, seed: seed < 2 and f < 3,
                               control=lambda f, s, seed: True)
    worse = summary.to_dict()["significantly_worse"]
    assert worse["start"]["worse"] and not worse["control"]["worse"] and worse["start"]["families"] == 4
    assert verdict.verdict == "REJECTED" and verdict.policy == "dv2s-ppo"
    assert verdict.decided_by == "heldout_vs_start"
    assert "significantly worse than the starting policy on the held-out families" in verdict.reason
    assert "one-sided exact McNemar tests per held-out family and pooled" in verdict.reason


def test_a_harm_confined_to_one_held_out_family_is_not_averaged_away():
    """Against the control the fine-tuned policy is better in three families and worse in every episode of the
    fourth; pooled the two cancel out, the family's own test finds it."""
    control = lambda f, s, seed: f < 3  # noqa: E731
    after = lambda f, s, seed: f == 3  # noqa: E731
    verdict, summary = _judged(before=lambda f, s, seed: True, after=after, control=control)
    test = summary.to_dict()["significantly_worse"]["control"]
    assert test["worse"] and test["worse_families"] == ["family_3"] and test["fine_tuned_only"] == 8
    assert verdict.verdict == "REJECTED" and verdict.decided_by == "heldout_vs_control"
    assert "family_3" in verdict.reason and "the control" in verdict.reason


def test_an_accepted_policy_passed_every_test_and_the_reason_names_them():
    verdict, summary = _judged(before=lambda f, s, seed: seed < 2, after=lambda f, s, seed: False,
                               control=lambda f, s, seed: seed < 1)
    assert not summary.to_dict()["significantly_worse"]["start"]["worse"]
    assert verdict.verdict == "ACCEPTED" and verdict.decided_by == "all"
    for text in ("regression test on the rest of the bank", "PASSed", "not significantly worse than the starting "
                 "policy", "not significantly worse than the control", "one-sided exact McNemar"):
        assert text in verdict.reason, text
    without_control, summary = _judged(before=lambda f, s, seed: seed < 2, after=lambda f, s, seed: False,
                                       control=None)
    assert summary.to_dict()["significantly_worse"]["control"] is None
    assert without_control.verdict == "ACCEPTED" and "no control arm" in without_control.reason


def test_held_out_tests_that_could_not_run_leave_the_policy_not_accepted():
    """Below the held-out minimums no test runs, so the regression test's PASS alone does not accept the policy."""
    verdict, summary = _judged(before=lambda f, s, seed: seed < 2, after=lambda f, s, seed: False,
                               control=lambda f, s, seed: seed < 1, min_families=5)
    assert summary.to_dict()["significantly_worse"] == {"start": None, "control": None} and summary.to_dict()["underpowered"]
    assert verdict.verdict == "NOT ACCEPTED" and verdict.decided_by == "heldout_vs_start"
    assert "did not run" in verdict.reason and "TOO SMALL TO JUDGE" in verdict.sentence


def test_a_policy_the_cross_round_check_rejected_is_never_the_policy_to_use():
    # rounds 1 and 2 each pass against their own start, but over rounds 1-2 round 2's policy regressed against the
    # starting one (recorded with round 2); round 3 then starts from the starting policy and fails its own test
    second = {**_round(2, "PASS"), "final_vs_start": {"verdict": "FAIL", "rounds": [1, 2], "reason": "worse"}}
    final = {"verdict": "PASS", "rounds": [1, 3], "reason": "no worse"}
    for last in ("FAIL", "INCONCLUSIVE"):
        verdict = recommendation(_report(_round(1, "PASS"), second, _round(3, last), final_vs_start=final))
        assert verdict.policy == "dv2s-ppo" and "keep the starting policy dv2s-ppo" in verdict.sentence
    # a later accepted round that passes the check is used again
    verdict = recommendation(_report(_round(1, "PASS"), second, _round(3, "PASS"), final_vs_start=final))
    assert verdict.verdict == "ACCEPTED" and verdict.policy == "ppo:round_3/policy/model.zip"


# --------------------------------------------------------------------------- the evidence floor
def test_the_evidence_floor_is_the_fewest_pairs_an_exact_mcnemar_test_can_be_significant_with():
    from dv2s_gym.loop.verdict import EVIDENCE_FLOOR, fewest_significant_pairs
    from dv2s_gym.regress.stats import PairedTable, mcnemar_exact

    assert EVIDENCE_FLOOR == fewest_significant_pairs(0.05) == 6
    # every pair discordant the one way: 5 cannot reach p < 0.05, 6 can
    assert mcnemar_exact(PairedTable(candidate_only=5)) >= 0.05 > mcnemar_exact(PairedTable(candidate_only=6))


def test_minimums_of_zero_do_not_let_a_single_held_out_pair_be_judged():
    """``--min-heldout-episodes 0 --min-heldout-families 0``: one tested pair (both policies pass) is too small to
    judge, not an ACCEPTED policy; the tests do not run and the verdict says why."""
    from dv2s_gym.loop.measures import heldout_comparison

    one = [{"scenario": "f0_s0", "seed": 0, "failed": False, "error": None}]
    summary = heldout_comparison(held(one), held(one), held(one), min_episodes=0, families={"f0_s0": "family_0"}, min_families=0)
    assert summary.to_dict()["pairs"] == 1 and summary.to_dict()["heldout_families"] == 1
    assert summary.to_dict()["significantly_worse"] == {"start": None, "control": None}
    assert "fewer than 6" in summary.to_dict()["underpowered"] and "cannot reach p < 0.05" in summary.to_dict()["underpowered"]
    record = {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
              "steps": {"fine_tune": {}, "after": summary, "regress": {"verdict": "PASS", "reason": "stand-in"}}}
    verdict = recommendation(_report(record))
    assert verdict.verdict == "NOT ACCEPTED" and "TOO SMALL TO JUDGE" in verdict.sentence
    # five pairs are still too few; six (all one family) are judged
    five = [{"scenario": "f0_s0", "seed": seed, "failed": False, "error": None} for seed in range(5)]
    assert heldout_comparison(held(five), held(five), None, min_episodes=0, min_families=0).underpowered
    six = five + [{"scenario": "f0_s0", "seed": 5, "failed": False, "error": None}]
    judged = heldout_comparison(held(six), held(six), None, min_episodes=0, min_families=0)
    assert "underpowered" not in judged.to_dict() and judged.to_dict()["significantly_worse"]["start"]["pairs"] == 6


def test_the_recommendation_is_a_record_written_as_a_json_object_and_every_report_has_one(tmp_path):
    from dv2s_gym.loop.run import LoopReport
    from dv2s_gym.loop.report import render_markdown
    from dv2s_gym.loop.settings import LoopError
    from dv2s_gym.loop.verdict import Recommendation

    body = _report(_round(1, "FAIL"), _round(2, "PASS"))
    verdict = recommendation(body)
    data = verdict.to_dict()
    assert list(data) == ["policy", "verdict", "round", "candidate", "reason", "decided_by", "exit_code", "too_small",
                          "sentence"]
    assert Recommendation.from_dict(data) == verdict and data["too_small"] is None and data["round"] == 2
    assert list(recommendation(LoopReportBody(rounds=())).to_dict()) == list(data)  # no round fine-tuned: the same fields
    with pytest.raises(LoopError, match=r"the loop report \(report.json\) holds no recommendation; .*rerun the loop"):
        render_markdown(body)  # no fallback: the loop writes the recommendation into every report
    with pytest.raises(LoopError, match="recommendation has no sentence"):
        Recommendation.from_dict({k: v for k, v in data.items() if k != "sentence"})
    written = tmp_path / "report.json"
    written.write_text('{"schema": "dv2s-loop", "rounds": []}')
    report = LoopReport(out=tmp_path, rounds=[], policy="p", paths={"json": written}, settings={"policy": "p"})
    with pytest.raises(LoopError, match=f"{written} holds no recommendation"):
        report.recommendation  # noqa: B018 - the property reads the file
    written.write_text(json.dumps({"recommendation": data}))
    assert report.recommendation == verdict


def test_a_minimum_that_can_never_give_evidence_is_flagged_in_the_help_the_log_and_the_report():
    from dv2s_gym.loop.report import render_markdown
    from dv2s_gym.loop.verdict import evidence_floor_note

    assert evidence_floor_note(20, 3) is None and evidence_floor_note(6, 1) is None
    note = evidence_floor_note(0, 0)
    assert "--min-heldout-episodes 0 is below 6" in note and "--min-heldout-families 0" in note
    text = render_markdown(written_report({"settings": {"policy": "dv2s-ppo", "min_heldout_episodes": 1,
                                                  "min_heldout_families": 3}, "policy": "dv2s-ppo", "rounds": []}))
    assert "WARNING: --min-heldout-episodes 1 is below 6" in text and "can never" not in text.split("WARNING")[0]
    assert "WARNING" not in render_markdown(written_report({"settings": {"policy": "dv2s-ppo", "min_heldout_episodes": 20,
                                                                   "min_heldout_families": 3}, "policy": "dv2s-ppo",
                                                      "rounds": []}))


def test_loop_help_says_below_what_minimum_no_test_can_be_significant(capsys):
    import pytest

    from dv2s_gym.cli import main

    with pytest.raises(SystemExit):
        main(["loop", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "never fewer than 6 tested pairs" in text and "cannot reach p < 0.05" in text


# --------------------------------------------------------------------------- the held-out families' harm rule
def test_a_harm_in_one_family_the_gate_calls_inconclusive_is_not_accepted():
    """The fine-tuned policy fails 3 of family_3's 8 pairs that the starting policy passed (+37.5 pp) and matches it
    everywhere else: one-sided p = 0.125, so no test finds it significantly worse, but its estimate is worse than the
    margin, so the round is not accepted (and the control, failing everything, changes nothing)."""
    after = lambda f, s, seed: f == 3 and s * 4 + seed < 3  # noqa: E731
    verdict, summary = _judged(before=lambda f, s, seed: False, after=after, control=lambda f, s, seed: True)
    start = summary.to_dict()["significantly_worse"]["start"]
    assert not start["worse"] and start["family_harm"]["harmed"] == ["family_3"]
    row = start["family_harm"]["families"]["family_3"]
    assert row["difference"] == pytest.approx(3 / 8) and not row["non_inferior"] and row["interval"][0] < 0
    assert not summary.to_dict()["significantly_worse"]["control"]["family_harm"]["harmed"]
    assert verdict.verdict == "NOT ACCEPTED" and verdict.decided_by == "heldout_families_vs_start"
    assert "in family family_3 the fine-tuned policy failed 3 of 8 pairs" in verdict.reason
    assert "Holm" in verdict.reason and verdict.policy == "dv2s-ppo"
    from dv2s_gym.loop.report import render_markdown

    record = {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
              "steps": {"fine_tune": {}, "after": summary, "regress": {"verdict": "PASS", "reason": "stand-in"}}}
    markdown = render_markdown(written_report(_report(record)))
    assert "**harm not ruled out in family_3**" in markdown and "family_3 +37.5 pp" in markdown
    # the same round judged at a margin the harm stays within is accepted
    from dv2s_gym.loop.measures import heldout_comparison

    families = {f"f{f}_s{s}": f"family_{f}" for f in range(4) for s in range(2)}
    wide = heldout_comparison(_episodes(lambda f, s, seed: False), _episodes(after), None, min_episodes=8,
                              families=families, min_families=3, margin=0.4)
    record = {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
              "steps": {"fine_tune": {}, "after": wide, "regress": {"verdict": "PASS", "reason": "stand-in"}}}
    assert recommendation(_report(record)).verdict == "ACCEPTED"


def test_a_harm_in_one_family_against_the_control_is_not_accepted_either():
    after = lambda f, s, seed: f == 0 and seed < 2  # noqa: E731  4 of family_0's 8 pairs
    verdict, summary = _judged(before=lambda f, s, seed: True, after=after, control=lambda f, s, seed: f > 0)
    assert not summary.to_dict()["significantly_worse"]["control"]["worse"]
    assert summary.to_dict()["significantly_worse"]["control"]["family_harm"]["harmed"] == ["family_0"]
    assert verdict.verdict == "NOT ACCEPTED" and verdict.decided_by == "heldout_families_vs_control"


def test_a_round_no_worse_in_any_family_is_still_accepted():
    """Discordant pairs both ways that cancel out in every family (estimate 0, within the margin, though too few
    pairs to show non-inferiority): the harm rule does not block it."""
    before = lambda f, s, seed: s == 0 and seed == 0  # noqa: E731
    after = lambda f, s, seed: s == 1 and seed == 0  # noqa: E731
    verdict, summary = _judged(before=before, after=after, control=None)
    harm = summary.to_dict()["significantly_worse"]["start"]["family_harm"]
    assert harm["harmed"] == [] and harm["non_inferior"] == []  # 8 pairs per family cannot show it at 2 pp
    assert all(row["difference"] == 0 for row in harm["families"].values())
    assert verdict.verdict == "ACCEPTED" and "no held-out family worse for the fine-tuned policy" in verdict.reason


def test_non_inferiority_p_is_below_the_level_exactly_when_the_interval_is_below_the_margin():
    from dv2s_gym.loop.verdict import family_harm, non_inferiority_p
    from dv2s_gym.regress.stats import PairedTable, paired_difference_interval

    for table in (PairedTable(neither=400), PairedTable(neither=150), PairedTable(both_fail=5, baseline_only=3,
                                                                                  neither=300),
                  PairedTable(candidate_only=1, neither=20), PairedTable(candidate_only=3, neither=5)):
        p = non_inferiority_p(table, 0.02)
        assert (p < 0.025) == (paired_difference_interval(table, 0.95)[1] < 0.02), table
    assert non_inferiority_p(PairedTable(candidate_only=3, neither=5), 0.02) == 1.0
    # Holm over the families: two families each shown alone at 2.5 % may not both be shown together
    big = PairedTable(neither=400)
    alone = non_inferiority_p(big, 0.02)
    both = family_harm({"a": big, "b": big}, 0.02)
    assert both.to_dict()["families"]["a"]["holm_p"] == pytest.approx(min(1.0, 2 * alone))
    assert both.to_dict()["non_inferior"] == (["a", "b"] if 2 * alone < 0.025 else [])


def _accepted_round():
    """A round every test accepts: 20 held-out pairs from 4 families, the fine-tuned policy failing none the start
    or the control passed."""
    from dv2s_gym.loop.measures import heldout_comparison

    families = {f"F{i}_replay": f"F{i}" for i in range(4)}
    before = [{"scenario": n, "seed": s, "failed": True, "error": None} for n in families for s in range(5)]
    after = [{"scenario": n, "seed": s, "failed": False, "error": None} for n in families for s in range(5)]
    summary = heldout_comparison(held(before), held(after), held(after), min_episodes=20, families=families, min_families=3)
    return {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
            "steps": {"fine_tune": {}, "after": summary, "regress": {"verdict": "PASS", "reason": "stand-in"}}}


def test_a_fine_tuned_policy_that_fails_on_the_untouched_set_is_not_accepted():
    record = _accepted_round()
    assert recommendation(_report(record)).verdict == "ACCEPTED"
    record["steps"]["untouched"] = {"fine_tuned_vs_start": {"verdict": "FAIL", "reason": "fails more often: +73 pp"}}
    verdict = recommendation(_report(record))
    assert verdict.verdict == "NOT ACCEPTED" and verdict.decided_by == "untouched"
    assert "untouched scenario set" in verdict.reason and "(fails more often: +73 pp)" in verdict.reason
    assert verdict.policy == "dv2s-ppo"
    record["steps"]["untouched"]["fine_tuned_vs_start"]["verdict"] = "PASS"
    assert recommendation(_report(record)).verdict == "ACCEPTED"


def test_an_untouched_set_the_start_failed_entirely_is_called_vacuous_in_the_verdict_and_the_report():
    from dv2s_gym.loop.record import UntouchedComparison
    from dv2s_gym.loop.report_text import _untouched_lines

    def policies(start_failed: int) -> dict:
        rate = {"value": start_failed / 6, "low": 0.0, "high": 1.0}
        return {"start": {"episodes": 6, "failure_rate": rate},
                "fine_tuned": {"episodes": 6, "failure_rate": {"value": 0.5, "low": 0.1, "high": 0.9}}}

    record = _accepted_round()
    record["steps"]["untouched"] = {"policies": policies(6), "fine_tuned_vs_start": {"verdict": "PASS", "reason": "r"}}
    verdict = recommendation(_report(record))
    assert verdict.verdict == "ACCEPTED"
    assert "on the untouched set the starting policy failed every untouched episode (6 of 6)" in verdict.reason
    assert "non-inferiority against it is vacuous" in verdict.reason
    lines = _untouched_lines(UntouchedComparison.from_dict({"scenarios": ["a"], "seeds": 6, "policies": policies(6)}))
    assert any(line.startswith("- **WARNING: the starting policy failed every untouched episode") for line in lines)
    record["steps"]["regress"]["verdict"] = "INCONCLUSIVE"  # whatever decides, the vacuous set is named
    held_back = recommendation(_report(record))
    assert held_back.verdict == "NOT ACCEPTED" and "non-inferiority against it is vacuous" in held_back.reason
    record["steps"]["regress"]["verdict"] = "PASS"
    record["steps"]["untouched"]["policies"] = policies(5)  # one passed: the comparison can fail, so it says something
    assert "vacuous" not in recommendation(_report(record)).reason
    lines = _untouched_lines(UntouchedComparison.from_dict({"scenarios": ["a"], "seeds": 6, "policies": policies(5)}))
    assert not any("WARNING" in line for line in lines)


def test_an_inconclusive_cross_round_check_is_named_in_the_reason():
    first, second = _accepted_round(), _accepted_round()
    second.update(round=2, policy=first["new_policy"], new_policy="ppo:round_2/policy/model.zip")
    final = {"verdict": "INCONCLUSIVE", "reason": "+6.0 pp, 95% CI -1 to +13 pp", "rounds": [1, 2]}
    verdict = recommendation(_report(first, second, final_vs_start=final))
    assert "over rounds 1, 2" in verdict.reason and "was INCONCLUSIVE (+6.0 pp, 95% CI -1 to +13 pp)" in verdict.reason
    assert "INCONCLUSIVE" in verdict.sentence


def test_loop_help_names_the_family_harm_rule_and_the_untouched_set(capsys):
    from dv2s_gym.cli import main

    with pytest.raises(SystemExit):
        main(["loop", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(per-family harm rule)" in text and "untouched scenario set" in text


# --------------------------------------------------------------------------- the harm rule at its boundaries
def _one_family_round(fine_tuned_only, *, pairs=50, other_only=0, margin=None):
    """A round with one held-out family ``F`` of ``pairs`` paired episodes and no control: the fine-tuned policy fails
    the first ``fine_tuned_only`` episodes alone, the starting policy the next ``other_only`` alone."""
    from dv2s_gym.loop.measures import heldout_comparison

    before = [{"scenario": "F_replay", "seed": s, "failed": fine_tuned_only <= s < fine_tuned_only + other_only,
               "error": None} for s in range(pairs)]
    after = [{"scenario": "F_replay", "seed": s, "failed": s < fine_tuned_only, "error": None} for s in range(pairs)]
    summary = heldout_comparison(held(before), held(after), None, min_episodes=pairs, families={"F_replay": "F"}, min_families=1,
                                 margin=margin)
    return {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
            "steps": {"fine_tune": {}, "after": summary, "regress": {"verdict": "PASS", "reason": "stand-in"}}}


@pytest.mark.parametrize("pairs, margin", [(50, None), (10, 0.1), (20, 0.15)])
def test_a_family_exactly_at_the_margin_is_not_harmed_and_one_pair_more_is(pairs, margin):
    """The default margin is 2 pp: one fine-tuned-only failure in 50 pairs is +2 pp, exactly the margin, and is no
    harm (the rule is "worse by more than the margin"); a second one (+4 pp) is. The same at margins 10 pp (1 of 10
    pairs) and 15 pp (3 of 20)."""
    from dv2s_gym.loop.settings import DEFAULTS

    limit = DEFAULTS["margin"] if margin is None else margin
    at = round(limit * pairs)
    assert at / pairs == limit  # the boundary is hit exactly, not by a rounding error
    equal = _one_family_round(at, pairs=pairs, margin=margin)
    test = equal["steps"]["after"].to_dict()["significantly_worse"]["start"]
    row = test["family_harm"]["families"]["F"]
    assert row["difference"] == limit and not row["harm"] and test["family_harm"]["harmed"] == []
    assert not test["worse"]  # the significance gate never fires here: only the harm rule decides
    verdict = recommendation(_report(equal))
    assert verdict.verdict == "ACCEPTED" and verdict.decided_by == "all"
    more = _one_family_round(at + 1, pairs=pairs, margin=margin)
    test = more["steps"]["after"].to_dict()["significantly_worse"]["start"]
    assert not test["worse"] and test["family_harm"]["harmed"] == ["F"]
    verdict = recommendation(_report(more))
    assert verdict.verdict == "NOT ACCEPTED" and verdict.decided_by == "heldout_families_vs_start"
    assert f"in family F the fine-tuned policy failed {at + 1} of {pairs} pairs" in verdict.reason
    assert verdict.policy == "dv2s-ppo" and verdict.exit_code == 3


def test_family_non_inferiority_is_shown_at_one_sided_2_5_percent_after_holm_and_the_report_says_so():
    """10 pairs, the starting policy failing alone 3 times (-30 pp): Holm-adjusted one-sided p is 0.031, between
    0.025 and 0.05, so non-inferiority at the margin is not shown (it would be at one-sided 0.05); 40 such pairs
    show it. The report's line on the family says which."""
    from dv2s_gym.loop.report import render_markdown
    from dv2s_gym.loop.verdict import family_harm, non_inferiority_p
    from dv2s_gym.regress.stats import PairedTable, paired_difference_interval

    record = _one_family_round(0, pairs=10, other_only=3)
    harm = record["steps"]["after"].to_dict()["significantly_worse"]["start"]["family_harm"]
    row = harm["families"]["F"]
    assert row["holm_p"] == row["non_inferiority_p"] == pytest.approx(0.0306, abs=5e-4)  # one family: Holm is p
    assert 0.025 < row["holm_p"] < 0.05
    assert not row["non_inferior"] and harm["non_inferior"] == [] and harm["harmed"] == []
    table = PairedTable(baseline_only=3, neither=7)
    assert row["interval"] == list(paired_difference_interval(table, 0.95))
    # the one-sided p is where the upper end of the two-sided interval crosses the margin
    assert paired_difference_interval(table, 1 - 2 * 0.0305)[1] > 0.02 > paired_difference_interval(
        table, 1 - 2 * 0.0307)[1]
    markdown = render_markdown(written_report(_report(record)))
    line = next(text for text in markdown.splitlines() if text.startswith("- held-out families against the starting"))
    assert "no family worse by more than the margin" in line and "F -30.0 pp (95% CI " in line
    assert line.endswith("; not shown)") and "one-sided 0.025" in line
    shown = _one_family_round(0, pairs=40, other_only=12)
    row = shown["steps"]["after"].to_dict()["significantly_worse"]["start"]["family_harm"]["families"]["F"]
    assert row["holm_p"] < 0.025 and row["non_inferior"]
    line = next(text for text in render_markdown(written_report(_report(shown))).splitlines()
                if text.startswith("- held-out families against the starting"))
    assert line.endswith("; non-inferior)")
    # Holm over two families doubles the smaller p: each alone is shown (p = 0.018), together neither is (0.035)
    alone = PairedTable(baseline_only=4, neither=16)
    p = non_inferiority_p(alone, 0.02)
    assert 0.0125 < p < 0.025 < 2 * p < 0.05
    both = family_harm({"a": alone, "b": alone}, 0.02)
    assert both.to_dict()["families"]["a"]["holm_p"] == pytest.approx(2 * p) and both.to_dict()["non_inferior"] == []
    assert family_harm({"a": alone}, 0.02).to_dict()["non_inferior"] == ["a"]


def test_the_point_estimate_alone_decides_harm_and_the_non_inferiority_test_never_overrides_it():
    """Over every paired table of up to 8 pairs and several margins: a family is harmed exactly when its difference
    exceeds the margin, and a harmed family never shows non-inferiority (its p-value is 1), so reporting the test
    beside the estimate changes no verdict."""
    from dv2s_gym.loop.verdict import FAMILY_RULE, family_harm, non_inferiority_p
    from dv2s_gym.regress.stats import PairedTable

    other = PairedTable(candidate_only=1, neither=1)  # a second family for Holm to adjust over
    for margin in (0.0, 0.02, 0.25):
        for n in range(1, 9):
            for c in range(n + 1):
                for b in range(n - c + 1):
                    table = PairedTable(candidate_only=c, baseline_only=b, neither=n - c - b)
                    row = family_harm({"f": table, "g": other}, margin).to_dict()["families"]["f"]
                    assert row["harm"] == (table.difference > margin), (table, margin)
                    if table.difference >= margin:
                        assert non_inferiority_p(table, margin) == 1.0 and not row["non_inferior"]
    assert "point estimate" in FAMILY_RULE and "deciding nothing" in FAMILY_RULE
    assert FAMILY_RULE.index("blocks ACCEPTED") < FAMILY_RULE.index("non-inferiority")


# --------------------------------------------------------------------------- every branch of the verdict, one at a time
def _held_out_test(against="start", **table):
    """A held-out test the fine-tuned policy passes (not worse, no family harmed) against ``against``."""
    counts = {"both_fail": 0, "candidate_only": 0, "baseline_only": 4, "neither": 16, **table}
    return heldout_worse({"F": counts}, against)


def _passed_round(after, **steps):
    return {"round": 1, "policy": "dv2s-ppo", "new_policy": "ppo:round_1/policy/model.zip",
            "steps": {"fine_tune": {}, "after": after, "regress": {"verdict": "PASS", "reason": "stand-in"}, **steps}}


def test_the_held_out_gate_has_no_margin_and_says_against_whom_and_where():
    from dv2s_gym.regress.stats import PairedTable

    assert heldout_worse({}, "start") is None  # no pairs, no test
    assert heldout_worse({"F": PairedTable()}, "start") is None
    start, control = _held_out_test("start", candidate_only=2, baseline_only=3), _held_out_test("control")
    assert "only the fine-tuned policy failed 2, only the starting policy 3; pooled one-sided p = " in start.to_dict()["reason"]
    assert "only the fine-tuned policy failed 0, only the control 4;" in control.to_dict()["reason"]
    assert start.to_dict()["reason"].endswith("; not significantly worse") and not start.to_dict()["worse"]
    # worse pooled only (no family on its own): no family is named
    spread = heldout_worse({name: PairedTable(candidate_only=2, neither=6) for name in "abcd"}, "start")
    assert spread.worse and spread.worse_families == () and spread.reason.endswith("; significantly worse")
    one = heldout_worse({"a": PairedTable(candidate_only=8), "b": PairedTable(neither=8)}, "control")
    assert one.worse and one.reason.endswith("significantly worse (in family a)")
    two = heldout_worse({"a": PairedTable(candidate_only=9), "b": PairedTable(candidate_only=9)}, "start")
    assert two.to_dict()["reason"].endswith("significantly worse (in families a, b)")
    # dv2s regress's gate with no margin: a small harm on many pairs is significantly worse
    # (+0.5 pp on 100,000 pairs, upper 95 % bound +0.56 pp), which the harm rule at the 2 pp margin lets through
    table = PairedTable(candidate_only=600, baseline_only=100, neither=99_300)
    many = heldout_worse({"F": table}, "start")
    assert many.to_dict()["worse"] and many.to_dict()["worse_families"] == ["F"] and many.to_dict()["family_harm"]["harmed"] == []
    assert heldout_worse({"F": table}, "start", margin=0.002).to_dict()["family_harm"]["harmed"] == ["F"]


def test_a_round_is_judged_once_it_fine_tuned_or_named_a_policy():
    from dv2s_gym.loop.verdict import Judgement, judge_round

    assert judge_round({"round": 1, "steps": {"mine": {}}}) is None and judge_round({"round": 1}) is None
    for record in ({"round": 1, "steps": {"fine_tune": {}}}, {"round": 1, "new_policy": "ppo:x", "steps": {}}):
        assert judge_round(record) == Judgement(verdict="NOT ACCEPTED", decided_by="regression",
                                                reason="the round has no regression test yet")


def test_a_held_out_test_that_did_not_run_says_which_and_why():
    from dv2s_gym.loop.verdict import judge_round

    tested = _held_out_test()
    cases = [  # (after, decided_by, the reason's words)
        ({"pairs": 0, "significantly_worse": {"start": None, "control": None}}, "heldout_vs_start",
         "against the starting policy did not run (no held-out pair ran)"),
        ({"pairs": 20, "significantly_worse": {"start": None, "control": None}}, "heldout_vs_start",
         "against the starting policy did not run (not recorded)"),
        ({"pairs": 3, "underpowered": "only 3 held-out episode(s)", "control": {"k": 1},
          "significantly_worse": {"start": None, "control": None}}, "heldout_vs_start",
         "against the starting policy and the control did not run (only 3 held-out episode(s))"),
        ({"pairs": 20, "control": {"k": 1}, "vs_control": {"underpowered": "against the control: only 4"},
          "significantly_worse": {"start": None, "control": None}}, "heldout_vs_start",
         "against the starting policy and the control did not run (not recorded)"),
        ({"pairs": 20, "control": {"k": 1}, "significantly_worse": {"start": tested, "control": None}},
         "heldout_vs_control", "against the control did not run (not recorded)"),
        ({"pairs": 20, "vs_control": {"underpowered": "against the control: only 4"},
          "significantly_worse": {"start": tested, "control": None}}, "heldout_vs_control",
         "against the control did not run (against the control: only 4)"),
        ({"pairs": 20, "vs_control": {}, "significantly_worse": {"start": tested, "control": None}},
         "heldout_vs_control", "against the control did not run (not recorded)"),
    ]
    for after, decided_by, words in cases:
        judged = judge_round(_passed_round(after))
        assert judged.verdict == "NOT ACCEPTED" and judged.decided_by == decided_by, after
        assert words + ", so a harm on the held-out families is not ruled out" in judged.reason, judged.reason
    # no control arm recorded at all: the test against the start is enough
    alone = judge_round(_passed_round({"pairs": 20, "significantly_worse": {"start": tested, "control": None}}))
    assert alone.verdict == "ACCEPTED" and alone.reason.endswith("; no control arm to compare with; no held-out "
                                                                     f"family worse for the fine-tuned policy by more "
                                                                     f"than the margin +2.0 pp ({FAMILY_RULE})")
    both = judge_round(_passed_round({"pairs": 20, "control": {"k": 1}, "vs_control": {},
                                      "significantly_worse": {"start": tested, "control": _held_out_test("control")}}))
    assert both.verdict == "ACCEPTED" and "no control arm" not in both.reason
    assert "not significantly worse than the starting policy (p = " in both.reason
    assert "and not significantly worse than the control (p = 1 on 20 held-out pairs from 1 family)" in both.reason


def test_the_cross_round_check_changes_only_an_accepted_verdict():
    final = {"verdict": "FAIL", "rounds": [1, 2], "reason": "worse"}
    kept = recommendation(_report(_round(1, "PASS"), _round(2, "INCONCLUSIVE"), final_vs_start=final))
    assert kept.verdict == "NOT ACCEPTED" and kept.decided_by == "regression"
    assert kept.policy == "ppo:round_1/policy/model.zip"
    passed = recommendation(_report(_round(1, "PASS"), _round(2, "PASS"),
                                    final_vs_start={"verdict": "PASS", "rounds": [1, 2], "reason": "no worse"}))
    alone = recommendation(_report(_round(2, "PASS")))
    assert passed.verdict == "ACCEPTED" and passed.reason == alone.reason and "INCONCLUSIVE" not in passed.reason
    # without the report's own check, the last round's recorded one applies
    last = {**_round(2, "PASS"), "final_vs_start": final}
    judged = recommendation(_report(_round(1, "PASS"), last))
    assert judged.verdict == "REJECTED" and judged.decided_by == "final_vs_start" and judged.policy == "dv2s-ppo"


def test_the_candidate_is_the_rounds_own_policy_and_only_a_not_accepted_round_is_too_small():
    unnamed = _round(1, "PASS")
    del unnamed["new_policy"]
    verdict = recommendation(_report(unnamed).replace(policy="ppo:loop/policy.zip"))
    assert verdict.verdict == "ACCEPTED" and verdict.policy == verdict.candidate == "ppo:loop/policy.zip"
    named = recommendation(_report(_round(1, "FAIL")).replace(policy="ppo:elsewhere.zip"))
    assert named.candidate == "ppo:round_1/policy/model.zip"
    rejected = _round(1, "FAIL")
    rejected["steps"]["after"]["underpowered"] = "only 5 held-out episode(s)"
    verdict = recommendation(_report(rejected))
    assert verdict.verdict == "REJECTED" and verdict.too_small is None and "TOO SMALL" not in verdict.sentence


def test_family_non_inferiority_at_the_edge_of_one_sided_2_5_percent():
    """55 pairs, the other policy failing alone 3 times: p = 0.02492, shown; 58 pairs with 7 and 2: p = 0.02501, not."""
    from dv2s_gym.loop.verdict import family_harm
    from dv2s_gym.regress.stats import PairedTable

    below = family_harm({"f": PairedTable(baseline_only=3, neither=52)}, 0.02).to_dict()["families"]["f"]
    above = family_harm({"f": PairedTable(candidate_only=2, baseline_only=7, neither=49)}, 0.02).to_dict()["families"]["f"]
    assert 0.0249 < below["holm_p"] < 0.025 < above["holm_p"] < 0.0251
    assert below["non_inferior"] and not above["non_inferior"] and not below["harm"] and not above["harm"]
