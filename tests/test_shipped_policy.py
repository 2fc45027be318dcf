"""The shipped PPO checkpoint (`dv2s-ppo`): its card is consistent and current, its evaluation
reproduces episode by episode, and it beats the keep-lane baseline on collisions with a
significant paired test."""

from __future__ import annotations

import pytest

from dv2s_gym.regress.stats import PairedTable, mcnemar_exact
from policies.model_card import (
    MEASURES,
    bank_version,
    evaluate_parallel,
    outcome_code,
    read_card,
    render_markdown,
)
from policies.registry import SHIPPED_CHECKPOINT, load_policy
from policies.stats import wilson_interval
from policies.training import EVAL_SEED_BASE, TRAIN_SEED_LOW
from scenario_bank.bank import Bank

CARD = read_card(SHIPPED_CHECKPOINT)
EVALUATION = CARD.evaluation.to_dict()
CANDIDATE = EVALUATION["candidate"]


def card_episodes():
    """The ``(scenario, seed)`` episodes the card's evaluation ran, in order."""
    base, seeds = int(EVALUATION["seed_base"]), int(EVALUATION["seeds_per_scenario"])
    return [(name, base + offset) for name in EVALUATION["scenarios"] for offset in range(seeds)]


def _codes(label: str) -> str:
    outcomes = EVALUATION["policies"][label]["outcomes"]
    return "".join(outcomes[name] for name in EVALUATION["scenarios"])


def _collisions(codes: str):
    return [c == "C" for c in codes]


@pytest.mark.slow
def test_the_shipped_checkpoint_is_small_loads_and_matches_the_env_it_was_trained_on():
    assert SHIPPED_CHECKPOINT.stat().st_size < 2 * 1024 * 1024
    assert (SHIPPED_CHECKPOINT.parent / "README.md").read_text(encoding="utf-8") == render_markdown(CARD)
    policy = load_policy("dv2s-ppo")
    assert CARD.algorithm == "ppo" and policy.card.algorithm == "ppo"
    from policies.evaluation import make_eval_env

    env = make_eval_env(EVALUATION["scenarios"][:1], config=CARD.env_config)
    try:
        policy.bind([env])  # raises PolicySpaceError if the spaces differ
    finally:
        env.close()


def test_the_card_describes_its_training_and_the_current_bank():
    training = CARD.training
    assert training["command"].startswith("dv2s train --algo ppo")
    assert training["steps"] > 0 and training["wall_time_s"] > 0 and training["seed"] == 0
    # trained on the whole bank as it is now: a changed script makes this card stale
    assert CARD.bank["version"] == bank_version(EVALUATION["scenarios"])["version"]
    assert EVALUATION["scenarios"] == sorted(CARD.bank["scenarios"]) == Bank().names()
    # held-out episodes: every scenario at least 20 seeds from EVAL_SEED_BASE, far below training seeds
    assert EVALUATION["seed_base"] == EVAL_SEED_BASE and EVALUATION["seeds_per_scenario"] >= 20
    assert max(seed for _, seed in card_episodes()) < TRAIN_SEED_LOW
    assert training["train_seed_range"][0] == TRAIN_SEED_LOW


def test_the_card_rates_follow_from_its_episode_outcomes():
    n_seeds = EVALUATION["seeds_per_scenario"]
    for label, data in EVALUATION["policies"].items():
        codes = _codes(label)
        assert len(codes) == EVALUATION["episodes_total"] == n_seeds * len(EVALUATION["scenarios"])
        for measure in MEASURES:
            rate = data["overall"][measure]
            events = {"collision": "C", "off_road": "O", "failure": "CO", "success": "S"}[measure]
            k = sum(c in events for c in codes)
            assert (rate["k"], rate["n"]) == (k, len(codes)), (label, measure)
            assert (rate["lo"], rate["hi"]) == pytest.approx(wilson_interval(k, len(codes)))
            assert rate["lo"] <= rate["rate"] <= rate["hi"]


def test_ppo_collides_significantly_less_than_keep_lane_per_the_card():
    table = PairedTable.from_outcomes(_collisions(_codes(CANDIDATE)), _collisions(_codes("keep_lane")))
    p = mcnemar_exact(table, alternative="less")
    assert table.candidate_only < table.baseline_only and p < 0.05
    assert EVALUATION["comparisons"]["keep_lane"]["collision"]["p_candidate_better"] == pytest.approx(p)
    # the card says where the policy does not beat the rule-based driver
    rule_sentences = [s for s in EVALUATION["summary"] if "rule" in s]
    assert rule_sentences and any("collision rate" in s for s in rule_sentences)


# The first seeds of every scenario: each card episode is deterministic, so a fixed subset rerun
# must end exactly as the card records, episode by episode (the card's rates and its paired test
# follow from those recorded outcomes: the two tests above).
RERUN_SEEDS_PER_SCENARIO = 3


@pytest.mark.slow
def test_rerunning_the_card_evaluation_reproduces_its_episodes_exactly():
    """PPO and keep-lane on the first seeds of every card scenario (the rule-based driver's figures
    are checked for consistency above): every rerun episode ends exactly as the card records it,
    which is stronger than rates inside the card's intervals."""
    base = EVALUATION["seed_base"]
    episodes = [(name, seed) for name, seed in card_episodes()
                if seed < base + RERUN_SEEDS_PER_SCENARIO]
    assert len(episodes) == RERUN_SEEDS_PER_SCENARIO * len(EVALUATION["scenarios"])
    for label in (CANDIDATE, "keep_lane"):
        spec = "dv2s-ppo" if label == CANDIDATE else label
        config = CARD.env_config if label == CANDIDATE else {k: v for k, v in CARD.env_config.items()
                                                                 if k != "action"}
        results = evaluate_parallel(spec, episodes, config=config, jobs=2)
        assert [(r.scenario, r.seed) for r in results] == episodes
        recorded = EVALUATION["policies"][label]["outcomes"]
        differing = [(r.scenario, r.seed, recorded[r.scenario][r.seed - base], outcome_code(r)) for r in results
                     if outcome_code(r) != recorded[r.scenario][r.seed - base]]
        assert differing == [], f"{label}: (scenario, seed, card, rerun) of the episodes that differ"
