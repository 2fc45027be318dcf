"""Which policy `dv2s loop` recommends after its rounds, and the exit status that says so."""

from __future__ import annotations

from dv2s_gym.mining.loop_verdict import recommendation


def _round(number, verdict, *, control_only=0, fine_tuned_only=0, p=None):
    return {"round": number, "policy": f"p{number - 1}", "new_policy": f"ppo:round_{number}/policy/model.zip",
            "steps": {"fine_tune": {}, "regress": {"verdict": verdict, "reason": f"reason {number}"},
                      "after": {"vs_control": {"table": {"control_only": control_only,
                                                         "fine_tuned_only": fine_tuned_only}, "mcnemar_p": p}}}}


def _report(*rounds, **extra):
    return {"settings": {"policy": "dv2s-ppo"}, "policy": rounds[-1].get("new_policy", "dv2s-ppo"),
            "rounds": list(rounds), **extra}


def test_the_last_accepted_policy_is_recommended_and_a_later_regression_is_not():
    verdict = recommendation(_report(_round(1, "PASS"), _round(2, "FAIL")))
    assert verdict["verdict"] == "REJECTED" and verdict["exit_code"] == 1
    assert verdict["policy"] == "ppo:round_1/policy/model.zip" and verdict["candidate"].startswith("ppo:round_2")
    assert "keep the last accepted policy ppo:round_1/policy/model.zip" in verdict["sentence"]
    assert "regressed on the rest of the bank (reason 2)" in verdict["sentence"]


def test_an_accepted_last_round_is_used():
    verdict = recommendation(_report(_round(1, "FAIL"), _round(2, "PASS")))
    assert verdict["verdict"] == "ACCEPTED" and verdict["exit_code"] == 0
    assert verdict["policy"] == "ppo:round_2/policy/model.zip"
    assert verdict["sentence"].startswith("ACCEPTED: use the round 2 fine-tuned policy ppo:round_2/policy/model.zip")


def test_rounds_that_each_pass_but_regress_against_the_start_over_all_rounds_are_rejected():
    final = {"verdict": "FAIL", "rounds": [1, 2], "reason": "fails more often"}
    verdict = recommendation(_report(_round(1, "PASS"), _round(2, "PASS"), final_vs_start=final))
    assert verdict["verdict"] == "REJECTED" and verdict["policy"] == "dv2s-ppo"
    assert "over rounds 1, 2 the fine-tuned policy regressed against the starting one" in verdict["reason"]


def test_a_control_that_fails_significantly_fewer_held_out_episodes_rejects_the_policy():
    beaten = recommendation(_report(_round(1, "PASS", control_only=0, fine_tuned_only=8, p=0.008)))
    assert beaten["verdict"] == "REJECTED" and "the control" in beaten["reason"] and beaten["policy"] == "dv2s-ppo"
    untested = recommendation(_report(_round(1, "PASS", control_only=0, fine_tuned_only=4, p=None)))
    assert untested["verdict"] == "ACCEPTED" and "not tested" in untested["reason"]


def test_an_inconclusive_test_or_no_fine_tuned_policy_is_not_accepted():
    inconclusive = recommendation(_report(_round(1, "INCONCLUSIVE")))
    assert inconclusive["verdict"] == "NOT ACCEPTED" and inconclusive["exit_code"] == 3
    assert inconclusive["policy"] == "dv2s-ppo" and "keep the starting policy dv2s-ppo" in inconclusive["sentence"]
    skipped = recommendation(_report({"round": 1, "steps": {"skipped": "nothing kept"}}))
    assert skipped["verdict"] == "NOT ACCEPTED" and skipped["policy"] == "dv2s-ppo" and skipped["round"] is None


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
    assert verdict["verdict"] == "NOT ACCEPTED" and "too few held-out episodes" in verdict["too_small"]
    assert "TOO SMALL TO JUDGE" in verdict["sentence"] and "dv2s loop --profile evidence" in verdict["sentence"]
    judged = recommendation(_report(_round(1, "PASS")))
    assert judged["too_small"] is None and "TOO SMALL" not in judged["sentence"]
    failed = recommendation(_report(_round(1, "FAIL")))
    assert failed["verdict"] == "REJECTED" and failed["too_small"] is None
