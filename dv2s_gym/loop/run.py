"""Closing the RL loop (``dv2s loop``): mine a policy's failures, grow the bank, fine-tune, measure.

One round, starting from policy ``P`` (an SB3 checkpoint spec, e.g. ``dv2s-ppo``):

a. **mine**: :func:`dv2s_gym.mining.miner.mine` runs ``P`` on sampled scenes of the starting
   bank's scenarios, clusters its failures, converts the representatives of at most
   ``max_conversions`` clusters (largest first; the rest are counted as not converted) through
   the D-V2S pipeline and adds the kept scenarios to the *working bank* (``out/bank``, a copy
   of the shipped bank, or the ``bank_dir`` given); every converted failure's scene is also kept
   exactly (its *exact replay* entry: the parent scenario narrowed around the failing parameters),
   and so is that of up to ``max_replays`` more clusters, the scenario families taking turns, each its largest
   cluster first (:func:`dv2s_gym.loop.replays.replay_clusters`: no video, description or script, only the narrowed
   parent checked to replay the failing episode step for step): these are mined scenarios of the
   round too, so a round whose conversions are all rejected still has families to split;
b. **split**: the newly kept scenarios (converted scripts and exact replays) are split by *family* (their parent bank scenario,
   :func:`dv2s_gym.loop.split.split_by_family`) into a fine-tuning part and a held-out part,
   deterministically from the seed; a family held out once stays held out;
c. **reference**, then **before**: the reference driver (:data:`~dv2s_gym.loop.measures.REFERENCE_DRIVER`, the
   DAgger teacher and the miner's reference) drives every held-out episode first; an episode it does not pass (any
   failure of the monitors, or an error) is left out of every held-out rate and test, counted and named
   (:func:`~dv2s_gym.loop.measures.reference_gate`: no imitation of the reference can fix a scene the reference
   fails, so its pair measures nothing); ``P`` runs on the held-out scenarios, ``k_eval`` evaluation seeds each
   (``EVAL_SEED_BASE + i``, never a training seed): failure rate (the miner's monitors) with
   a Wilson interval; fewer than ``min_heldout_episodes`` held-out episodes is said loudly and
   the round reports rates but no drop and no test;
d. **fine-tune**: :func:`policies.training.fine_tune` continues ``P`` on the working bank
   minus every held-out scenario and every held-out family's parent scenario (so the parent over
   its full range cannot leak the held-out failures), the mined fine-tuning scenarios drawn with ``mined_share``
   of the probability, the rest of the bank with the remainder (so it is not forgotten).
   The training reward is ``P``'s own with the terms of ``fine_tune_reward`` overridden
   (default ``{"standing": -0.3}``: standing still with a free path ahead, the miner's
   stall, is penalised like the monitors count it); only fine-tuning uses that env config:
   mining, the held-out evaluations and the regression test run ``P``'s own (a failure
   does not depend on the reward). That is ``fine_tune_method="ppo"``; with ``"dagger"``
   the policy instead imitates the reference driver (``rule``) on the states it visits
   itself in the same weighted scenario mix (:mod:`policies.imitation`; no reward; a killed
   DAgger run resumes from its last finished iteration, ``resumed`` in the step's record);
d'. **control**: the same fine-tuning (method, steps, seed, learning rate) on the same scenarios
   less every mined one, into ``round_<r>/control``: what the fine-tuning does without the mined
   scenarios, so a drop can be credited to them (``control=False`` leaves it out);
e. **after**: the fine-tuned policy and the control run on the same held-out episodes (paired):
   rates with Wilson intervals for start, control and fine-tuned, relative drop
   (scenario-bootstrap interval), exact two-sided McNemar p fine-tuned vs start and fine-tuned
   vs control;
e'. **untouched**: start, control and fine-tuned run on the scenario set the loop never mines or
   fine-tunes on (:data:`~dv2s_gym.loop.comparisons.UNTOUCHED_BANK`: scripts written by others for Scenic's CARLA
   model),
   ``untouched_seeds`` seeds each, judged by :func:`dv2s_gym.regress.runner.run_regression`
   (failure rates, stalls apart, mean speed; fine-tuned vs start and control vs fine-tuned);
f. **regress**: :func:`dv2s_gym.regress.runner.run_regression` new against old on the starting
   bank's scenarios (PASS / FAIL / INCONCLUSIVE against ``margin``);
g. the next round starts from the policy the verdict on this round recommends
   (:func:`dv2s_gym.loop.verdict.recommendation` over the rounds so far): the fine-tuned policy when it
   was ACCEPTED, else the last accepted one, else the starting policy (``next_policy`` and
   ``next_policy_reason`` in the round's record).

Everything lives under ``out``: ``loop.json`` (settings and every finished step, written
atomically after each), ``bank/``, ``round_<r>/{mine,heldout.jsonl,policy,control,untouched,regress}`` and the
report (``report.json``, ``report.md``, ``report.html``).
Restarted with the same ``out`` and settings, the loop skips finished steps and resumes the
unfinished one (the miner, the held-out store, training and the regression run are each
resumable); ``rounds`` may be raised to add rounds to a finished loop.

The parts: :mod:`~dv2s_gym.loop.state` (``loop.json`` and the loop being run), :mod:`~dv2s_gym.loop.steps` (the
round's steps), :mod:`~dv2s_gym.loop.mined` (what mining kept), :mod:`~dv2s_gym.loop.arms` (the fine-tuning arms),
:mod:`~dv2s_gym.loop.measures` (the held-out measurements) and :mod:`~dv2s_gym.loop.comparisons` (the untouched set
and the regression test); this module runs the rounds and writes the reports.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from dv2s_gym.loop import report as loop_report
from dv2s_gym.loop.record import LoopReportBody, LoopStart, RecordedLoopSettings, RoundRecord, recorded
from dv2s_gym.loop.report import write_loop_reports
from dv2s_gym.loop.settings import LoopError, LoopSettings
from dv2s_gym.loop.state import HOLDOUT_BY, STAGE_NAMES, LoopState, RunningLoop, earlier_round_spec, working_bank
from dv2s_gym.loop.steps import (Timed, log_errored, log_mined, log_round, mine_plan, mine_step, skip_round,
                                 split_step, tune_and_measure)
from dv2s_gym.loop.verdict import Recommendation, evidence_floor_note, recommendation
from dv2s_gym.progress_lines import log_line
from dv2s_gym.workers.pool import default_workers
from scenario_bank import select_scenarios
from scenario_bank.bank import Bank
from scenario_bank.run_identity import BANK_IDENTITY, bank_identity, check_bank_unchanged
from policies.run_identity import RESUME_FINGERPRINT, resume_fingerprint

__all__ = ["LoopReport", "run_loop", "DEFAULT_OUT"]

DEFAULT_OUT = "out/loop"
"""Where ``dv2s loop`` writes when ``--out`` is not given (rerunning resumes it)."""


@dataclasses.dataclass
class LoopReport:
    """What :func:`run_loop` returns: the rounds' records and where the reports are."""

    out: Path
    rounds: List[RoundRecord]
    policy: str
    """The spec of the last round's fine-tuned policy (the starting policy if no round fine-tuned); the policy to
    use is :attr:`recommendation`'s."""
    paths: Dict[str, Path]
    settings: RecordedLoopSettings
    """The loop's settings as ``loop.json`` records them."""

    def to_json(self) -> Dict[str, Any]:
        """A JSON-safe dict (the body of ``report.json``)."""
        body = {"schema": "dv2s-loop", "schema_version": 1, "out": str(self.out),
                "settings": self.settings.to_dict(), "policy": self.policy,
                "rounds": [record.to_dict() for record in self.rounds]}
        return {**body, "recommendation": recommendation(LoopReportBody.from_dict(body)).to_dict()}

    @property
    def recommendation(self) -> Recommendation:
        """Which policy to use and why (:func:`dv2s_gym.loop.verdict.recommendation`), as ``report.json``
        has it once written (with the final-vs-starting comparison of two or more rounds); a written report without
        one is a :class:`LoopError` naming it."""
        path = self.paths.get("json")
        if path is not None and Path(path).is_file():
            written = json.loads(Path(path).read_text(encoding="utf-8")).get("recommendation")
            return Recommendation.from_dict(written, source=str(path))
        return recommendation(LoopReportBody.from_dict(self.to_json()))


def _log_default(line: str) -> None:
    log_line(line)


def run_loop(policy: str = "dv2s-ppo", settings: Optional[LoopSettings] = None, *,
             out: os.PathLike | str = DEFAULT_OUT, progress: bool = True,
             log: Callable[[str], None] = _log_default) -> LoopReport:
    """Run ``settings.rounds`` rounds of mine -> split -> evaluate -> fine-tune (+ control) -> evaluate -> regress
    (module docstring).

    Args:
        policy: the starting policy, an SB3 checkpoint spec (``dv2s-ppo``, ``ppo:PATH``, a run folder).
        settings: the loop's :class:`~dv2s_gym.loop.settings.LoopSettings` (default: its defaults).
        out: the loop folder (resumable).
        progress: progress bars on stderr.
        log: where the progress lines go (default stderr).

    Returns:
        A :class:`LoopReport`; the reports are written to ``out`` after every round.
    """
    settings = settings or LoopSettings()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise LoopError(f"--out {out} is a file; choose a folder for the loop")
    loop = _open_loop(policy, settings, out, progress, log)

    note = evidence_floor_note(settings.min_heldout_episodes, settings.min_heldout_families)
    if note:
        log(f"WARNING: {note}")
    current = policy
    for number in range(1, settings.rounds + 1):
        current = _run_round(loop, number, current)
    return _write(out, loop.state)


def _policy_env_config(spec: str) -> Dict[str, Any]:
    from policies.training import TrainingError, resolve_checkpoint

    try:
        _, _, card = resolve_checkpoint(spec)
    except TrainingError as error:
        raise LoopError(f"dv2s loop fine-tunes the policy, so it needs a stable-baselines3 checkpoint "
                        f"(dv2s-ppo, ppo:PATH or a `dv2s train` folder): {error}") from None
    return dict(card.env_config or {})


def _open_loop(policy: str, settings: LoopSettings, out: Path, progress: bool,
               log: Callable[[str], None]) -> RunningLoop:
    """The loop in ``out``: a new one recorded in ``loop.json``, or the recorded one checked against ``settings``;
    its working bank and starting scenarios."""
    from policies.training import TrainingError, with_reward_weights

    workers = int(settings.workers or default_workers())
    env_config = _policy_env_config(policy)
    try:
        fine_tune_config = with_reward_weights(env_config, settings.fine_tune_reward)
    except TrainingError as error:
        raise LoopError(f"--fine-tune-reward: {error}") from None
    state = LoopState(out / "loop.json", _recorded_settings(policy, settings, workers, env_config, fine_tune_config))
    bank = working_bank(out, state.settings.bank_dir)
    if state.start is None:
        names = sorted(select_scenarios(list(settings.scenarios) if settings.scenarios is not None else None, bank,
                                           command="dv2s loop"))
        if not names:
            raise LoopError("the scenario selection is empty; name bank scenarios or tag:<tag>")
        state.start = LoopStart(bank=bank, scenarios=tuple(names))
        state.save()
    scripts = bank_identity(Bank(bank), state.start.scenarios)  # the starting scenarios of the working bank
    if BANK_IDENTITY in state.extra:
        check_bank_unchanged(state.extra[BANK_IDENTITY], scripts, run=f"{out} holds a loop", error=LoopError)
    else:
        state.extra[BANK_IDENTITY] = scripts
        state.save()
    return RunningLoop(settings=settings, state=state, out=out, bank=bank, start_names=list(state.start.scenarios),
                       env_config=env_config, fine_tune_config=fine_tune_config, workers=workers, progress=progress,
                       log=log)


def _recorded_settings(policy: str, settings: LoopSettings, workers: int, env_config: Dict[str, Any],
                       fine_tune_config: Dict[str, Any]) -> Dict[str, Any]:
    """The ``settings`` of ``loop.json``: :meth:`LoopSettings.recorded` with the policy, the resolved number of
    workers, how mined scenarios are held out and the env configs (the keys :data:`~dv2s_gym.loop.state.IDENTITY`
    names are the loop's identity) and the starting policy's fingerprint
    (:func:`~policies.run_identity.resume_fingerprint`)."""
    return {"policy": policy, **settings.recorded(), "workers": workers, "holdout_by": HOLDOUT_BY,
            "env_config": env_config, "fine_tune_env_config": fine_tune_config,
            RESUME_FINGERPRINT: resume_fingerprint(policy)}


def _run_round(loop: RunningLoop, number: int, current: str) -> str:
    """Run (or finish) round ``number`` from policy ``current``; the policy the next round starts from."""
    record = loop.state.round(number)
    steps = record.steps
    if recorded(steps) and record.policy not in (None, current):
        raise LoopError(f"round {number} in {loop.out / 'loop.json'} was begun from {record.policy}, not from "
                        f"{current}, the policy the rounds before it recommend; choose another --out")
    if record.policy is None and "policy" not in (record.null_fields or ()):
        loop.state.update(record.replace(policy=current), save=False)
    round_dir = loop.out / f"round_{number}"
    if steps.done("regress") or steps.skipped:
        return _next_start(loop, number, current)
    loop.log(f"round {number}: policy {current}")
    timed = Timed(loop, number)
    done = [STAGE_NAMES[step] for step in timed.stages if steps.done(step)]
    if done:
        loop.log(f"round {number}: resuming: {len(done)} of {len(timed.stages)} steps already done and kept "
                 f"({', '.join(done)}); an interrupted step carries on from what it had kept")
    if not steps.done("mine"):
        mined = timed("mine", lambda: mine_step(loop, number, current, round_dir), mine_plan(loop))
        log_mined(loop, number, mined)
        log_errored(loop, number, "mining", {"mine": mined.errored})
    if not timed.steps.done("split"):
        split_step(loop, number, current, timed)
    if not timed.steps.split.fine_tune_scenarios and not timed.steps.split.held_out_scenarios:
        skip_round(loop, number, timed.steps)
    else:
        tune_and_measure(loop, number, current, round_dir, timed)
        log_round(loop.log, number, timed.steps)
    following = _next_start(loop, number, current)
    if number < loop.settings.rounds:
        loop.log(f"round {number}: round {number + 1} starts from {following}: "
                 f"{loop.state.round(number).next_policy_reason}")
    _write(loop.out, loop.state)
    return following


def _next_start(loop: RunningLoop, number: int, current: str) -> str:
    """The policy round ``number + 1`` starts from: the one the verdict on rounds 1..``number`` recommends
    (:func:`~dv2s_gym.loop.verdict.recommendation`: never a REJECTED or NOT ACCEPTED fine-tuned policy),
    recorded in round ``number``'s ``next_policy`` and ``next_policy_reason``."""
    rounds = loop.state.rounds[:number]
    record = rounds[-1]
    start = loop.state.settings.policy
    # as the report judges it: the cross-round check on each accepted round's policy
    body = loop_report.with_cross_round_checks(LoopReportBody.from_dict({"settings": {"policy": start},
                                                "rounds": [r.to_dict() for r in rounds]}), folder=loop.out)
    advice = recommendation(body)
    # the policy to use, exactly as the report recommends it: the fine-tuned one only when it is the recommendation
    following = advice.policy
    if not record.fine_tuned:
        reason = f"this round fine-tuned no policy; {advice.sentence}"
    else:
        reason = advice.sentence
    if following != start:
        following = earlier_round_spec(following, loop, number + 1)
    if (record.next_policy, record.next_policy_reason) != (following, reason):
        loop.state.update(record.replace(next_policy=following, next_policy_reason=reason))
    return following


def _write(out: Path, state: LoopState) -> LoopReport:
    tuned = [r.new_policy for r in state.rounds if r.new_policy]
    last = tuned[-1] if tuned else state.settings.policy
    report = LoopReport(out=out, rounds=list(state.rounds), policy=last, paths={}, settings=state.settings)
    report.paths = write_loop_reports(LoopReportBody.from_dict(report.to_json()), out)
    return report
