"""The steps of a loop's round (:mod:`dv2s_gym.loop.run`'s docstring): each run, timed and recorded in
``loop.json`` by :class:`Timed`: mining (:func:`mine_step`), the split by family (:func:`split_step`), then
(:func:`tune_and_measure`) the reference driver, the held-out ``before``, the two fine-tuning arms, the held-out
``after``, the untouched set and the regression test; and the lines each step logs."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

from dv2s_gym.mining import miner
from dv2s_gym.loop import heldout
from dv2s_gym.loop.arms import Arm, fine_tune_arm
from dv2s_gym.loop.comparisons import UNTOUCHED_BANK, evaluate_untouched, regress_step, untouched_settings
from dv2s_gym.loop.errored import errored_episodes, merged_messages, messages_text
from dv2s_gym.loop.heldout import HeldOutStore
from dv2s_gym.loop.measures import REFERENCE_DRIVER, heldout_comparison, reference_gate, underpowered
from dv2s_gym.loop.mined import mined_entries, mining_summary, with_parents
from dv2s_gym.loop.record import (ErroredEpisodes, HeldOutBefore, HeldOutComparison, MinedEntry, MiningSummary,
                                  ReferenceGate, RegressSummary, RoundSteps, SplitRecord, recorded)
from dv2s_gym.loop.replays import replay_clusters
from dv2s_gym.loop.report import errored_note, errored_text, rate_text, reference_gate_text
from dv2s_gym.loop.split import family_of, split_by_family
from dv2s_gym.loop.state import STAGE_NAMES, RunningLoop, earlier_sides, lineage, round_spec
from dv2s_gym.mining.miner import MineSettings, RunOrigin
from dv2s_gym.mining.settings import SETTINGS_FILE
from dv2s_gym.regress.store import RUN_FILE
from dv2s_gym.workers.settings import WorkerSettings
from policies.evaluation import EVAL_SEED_BASE

__all__ = ["Timed", "mine_step", "mine_plan", "log_errored", "log_mined", "split_step", "skip_round",
           "tune_and_measure", "log_round"]


class Timed:
    """Runs one step of a round: logs it, times it, records its value in ``loop.json``."""

    def __init__(self, loop: RunningLoop, number: int) -> None:
        self.loop, self.number = loop, number
        control, untouched = loop.settings.control, loop.settings.untouched_seeds
        self.stages = ["mine", "split", "reference", "before", "fine_tune"] + (["control"] if control else []) + ["after"] + (
            ["untouched"] if untouched else []) + ["regress"]

    def __call__(self, step: str, function: Callable[[], Any], plan: str = "") -> Any:
        """Run ``function`` as ``step``; ``plan`` says what it will do (its size), in the step's opening line."""
        log, state = self.loop.log, self.loop.state
        where = f"round {self.number} [{self.stages.index(step) + 1}/{len(self.stages)}] {STAGE_NAMES[step]}"
        log(f"{where}: {plan} ..." if plan else f"{where} ...")
        began = time.perf_counter()
        value = function()
        seconds = round(time.perf_counter() - began, 1)  # of the run that finished the step
        # the files the step's code read join loop.json in the same write that marks the step done
        state.add_reads(records=_step_records(self.loop.out / f"round_{self.number}", step))
        state.update(state.round(self.number).with_step(step, value, seconds))
        log(f"{where}: done in {seconds:.0f} s")
        return value

    @property
    def steps(self) -> RoundSteps:
        """The round's steps as recorded so far."""
        return self.loop.state.round(self.number).steps


def _step_records(round_dir: Path, step: str) -> List[Path]:
    """The records of the runs a step made, each holding the user's files its workers read: the mining run's
    ``settings.json``, the regression runs' ``run.json``."""
    runs = {"mine": [round_dir / "mine" / SETTINGS_FILE], "regress": [round_dir / "regress" / RUN_FILE],
            "untouched": [round_dir / "untouched" / side / RUN_FILE for side in ("vs_start", "vs_control")]}
    return runs.get(step, [])


def mine_step(loop: RunningLoop, number: int, current: str, round_dir: Path) -> MiningSummary:
    """The ``mine`` step: mine ``current``'s failures into the working bank, keep exact replays of more."""
    s = loop.settings
    miner.mine(current, MineSettings(budget=s.budget, sampler=s.sampler, scenarios=loop.start_names,
                                     bank_dir=loop.bank, seed=s.seed * 1000 + number, env_config=loop.env_config,
                                     convert=True, max_conversions=s.max_conversions),
               out=str(round_dir / "mine"), workers=WorkerSettings(workers=loop.workers), progress=loop.progress,
               origin=RunOrigin(command="dv2s loop", seed=s.seed, round=number))
    if s.max_replays != 0 and (round_dir / "mine" / "settings.json").is_file():  # a miner's run folder
        replay_clusters(round_dir / "mine", bank_dir=loop.bank, max_replays=s.max_replays, progress=loop.progress)
    return mining_summary(round_dir / "mine").replace(kept=tuple(mined_entries(round_dir / "mine")),
                                                      folder=str(round_dir / "mine"))


def mine_plan(loop: RunningLoop) -> str:
    """What the ``mine`` step will do, in words."""
    s = loop.settings

    def most(count: Optional[int], what: str) -> str:
        return f"every cluster {what}" if count is None else f"at most {count} cluster(s) {what}"

    return (f"{s.budget} episodes on {len(loop.start_names)} scenarios ({s.sampler} sampler), then "
            f"{most(s.max_conversions, 'converted')} and {most(s.max_replays, 'kept as exact replays')}")


def log_errored(loop: RunningLoop, number: int, stage: str, errored: Mapping[str, Optional[ErroredEpisodes]]) -> None:
    """Say loudly when a step's episodes errored: they count in no rate and no test."""
    text = errored_text(errored)
    if not text:
        return
    merged = merged_messages([found for found in errored.values() if recorded(found)])
    loop.log(f"round {number}: WARNING: episodes that errored in the {stage} step (left out of its rates and "
             f"tests): {text}" + "".join(f"; {name}: {messages_text(merged, name)}" for name in merged))


def log_mined(loop: RunningLoop, number: int, mined: MiningSummary) -> None:
    """Log what the ``mine`` step found and kept: failures, clusters, converted scenarios and exact replays, and
    the clusters neither converted nor replayed (with why, when the reference driver failed them too)."""
    s = loop.settings
    loop.log(f"round {number}: mined {mined.failures} failures in {mined.episodes} episodes"
             f"{errored_note(mined.errored)}, "
             f"{mined.clusters} clusters, "
             f"{len({e.scenario for e in mined.converted})} converted scenarios and "
             f"{len({e.scenario for e in mined.replayed})} exact replays kept"
             + (f"; {mined.clusters_not_converted} clusters not converted (--max-conversions "
                f"{'all' if s.max_conversions is None else s.max_conversions})"
                if mined.clusters_not_converted else "")
             + (f", {mined.clusters_not_kept} neither converted nor replayed (--max-replays "
                f"{'all' if s.max_replays is None else s.max_replays}"
                + (f"; {mined.clusters_reference_failed} of them because the reference driver {REFERENCE_DRIVER} "
                   "did not pass any of their failing scenes" if mined.clusters_reference_failed else "")
                + ")" if mined.clusters_not_kept else ""))


def split_step(loop: RunningLoop, number: int, current: str, timed: "Timed") -> None:
    """Split the round's kept scenarios into fine-tuning and held-out families. Families an earlier round held
    out stay held out where they can; families fine-tuned on by a round ``current`` descends from
    (:func:`lineage`) cannot be held out; a discarded round's fine-tuning does not count."""
    earlier = loop.state.rounds[:number - 1]
    held_families, _ = earlier_sides(earlier)
    _, tuned_families = earlier_sides(lineage(loop, earlier, current))
    kept = timed.steps.mine.kept_entries
    split = timed("split", lambda: split_by_family(with_parents(kept, loop.bank), loop.settings.holdout_fraction,
                                                   loop.settings.seed * 1000 + number, held_families,
                                                   tuned_families).record(),
                  f"{len(kept)} kept mined scenario(s) into fine-tuning and held-out families")
    families = set(split.fine_tune_family_names)  # every kept family, when none is held out
    if kept and not split.held_out_scenarios and families and families <= set(tuned_families) - set(held_families):
        loop.log(f"round {number}: WARNING: nothing can be held out: every kept scenario's family "
                 f"({', '.join(sorted(families))}) was fine-tuned on by an earlier round that {current} descends from")
    if split.moved_to_fine_tune:
        loop.log(f"round {number}: WARNING: earlier held-out famil(ies) "
                 f"{', '.join(split.moved_to_fine_tune)} now share a mined scenario with a family "
                 "fine-tuned on earlier, so they are fine-tuned on from this round")


def skip_round(loop: RunningLoop, number: int, steps: RoundSteps) -> None:
    """Record and log a round that kept no mined scenario (nothing to fine-tune on or to measure)."""
    mined = steps.mine
    tried = sum((mined.conversions or {}).values())
    replayed = sum((mined.replays or {}).values())
    skipped = (f"no mined scenario was kept this round ({tried} conversion(s) tried"
               + (f", {replayed} exact replay(s) tried" if replayed else "")
               + (f", {mined.clusters_not_converted} cluster(s) not converted: raise "
                  "--max-conversions, --max-replays or --budget"
                  if mined.clusters_not_converted else "")
               + "): nothing to fine-tune on or to measure")
    loop.state.update(loop.state.round(number).with_step("skipped", skipped))
    loop.log(f"round {number}: {skipped}")


def tune_and_measure(loop: RunningLoop, number: int, current: str, round_dir: Path, timed: Timed) -> str:
    """The steps after the split: held-out before, fine-tune (+ control), held-out after, untouched set,
    regression; the fine-tuned policy's spec."""
    s, split = loop.settings, timed.steps.split
    episodes = [(name, EVAL_SEED_BASE + i) for name in split.held_out_scenarios for i in range(s.k_eval)]
    families = _families_of(timed.steps.mine.kept_entries, split.held_out_scenarios, loop.bank)
    store_path = round_dir / "heldout.jsonl"

    def held_out() -> HeldOutStore:  # what its workers read joins loop.json before each episode is saved
        return HeldOutStore(store_path, on_reads=loop.state.record_reads)

    if not timed.steps.done("reference"):
        gate = timed("reference", lambda: _reference_step(loop, episodes, held_out(), families),
                     f"{len(episodes)} episodes ({len(split.held_out_scenarios)} held-out scenario(s) x {s.k_eval} seeds) "
                     f"for the reference driver {REFERENCE_DRIVER}: a held-out episode it does not pass is left out")
        _log_reference(loop, number, gate)
    excluded = timed.steps.reference.excluded_episodes
    episodes = [episode for episode in episodes if episode not in excluded]
    shortfall = underpowered(len(episodes), s.min_heldout_episodes,
                             len({families[name] for name, _ in episodes}), s.min_heldout_families)
    if shortfall:
        loop.log(f"round {number}: WARNING: {shortfall}")
    if not timed.steps.done("before"):
        def before_step() -> HeldOutBefore:
            records = heldout.evaluate_heldout("before", current, episodes, store=held_out(),
                                               bank_dir=loop.bank, env_config=loop.env_config,
                                               workers=WorkerSettings(workers=loop.workers), progress=loop.progress)
            return HeldOutBefore(episodes=len(episodes), done=bool(records), errored=errored_episodes(records))

        before = timed("before", before_step,
                       f"{len(episodes)} episodes ({len(split.held_out_scenarios)} held-out scenario(s) x {s.k_eval} seeds"
                       + (f", {len(excluded)} left out: the reference driver does not pass them" if excluded else "")
                       + ")")
        log_errored(loop, number, "held-out: starting policy", {"start": before.errored})
    new_policy, control_policy = _fine_tune_arms(loop, number, current, round_dir, timed)
    policies = {"before": current, "after": new_policy, "control": control_policy}
    if not timed.steps.done("after"):
        after = timed("after", lambda: _after_step(loop, policies, episodes, held_out(), families),
                      f"{len(episodes)} episodes for the fine-tuned policy" + (" and as many for the control"
                                                                               if control_policy else ""))
        log_errored(loop, number, "held-out: fine-tuned and control", after.errored or {})
    if s.untouched_seeds and not timed.steps.done("untouched"):
        untouched = timed("untouched", lambda: evaluate_untouched(
            current, new_policy, control_policy, settings=untouched_settings(s.untouched_seeds, loop.env_config,
                                                                             s.margin),
            out=round_dir / "untouched", workers=loop.workers, progress=loop.progress),
              f"{_count_scripts(UNTOUCHED_BANK)} scripts x {s.untouched_seeds} seed(s) for the starting, fine-tuned"
              + (" and control policies" if control_policy else " policies"))
        log_errored(loop, number, "untouched scenario set", untouched.errored or {})
    if not timed.steps.done("regress"):
        regress = timed("regress", lambda: regress_step(loop, new_policy, current, round_dir, split),
                        f"{len(loop.start_names)} scenarios x {s.regress_episodes} seed(s), fine-tuned against "
                        "starting policy")
        log_errored(loop, number, "regression test", regress.errored or {})
    return new_policy


def _families_of(kept: Sequence[MinedEntry], held_out: Sequence[str], bank: Optional[str]) -> Dict[str, str]:
    """``{held-out scenario: its family}`` (:func:`dv2s_gym.loop.split.family_of`)."""
    wanted = set(held_out)
    families = {str(e.scenario): family_of(e) for e in with_parents(kept, bank) if e.scenario in wanted}
    return {name: families.get(name, name) for name in held_out}


def _count_scripts(bank: Path) -> int:
    return sum(1 for _ in Path(bank).glob("*/scenario.scenic"))


def _reference_step(loop: RunningLoop, episodes: List[tuple], store, families: Mapping[str, str]) -> ReferenceGate:
    """The ``reference`` step: the reference driver on every held-out episode (role ``reference`` in the
    held-out store); :func:`reference_gate`'s record."""
    records = heldout.evaluate_heldout("reference", REFERENCE_DRIVER, episodes, store=store, bank_dir=loop.bank,
                                       env_config=loop.env_config, workers=WorkerSettings(workers=loop.workers),
                                       progress=loop.progress)
    return reference_gate(records, families)


def _log_reference(loop: RunningLoop, number: int, gate: ReferenceGate) -> None:
    text = reference_gate_text(gate)
    loop.log(f"round {number}: {'WARNING: ' if gate.excluded else ''}{text}")


def _fine_tune_arms(loop: RunningLoop, number: int, current: str, round_dir: Path, timed: Timed) -> tuple:
    """The ``fine_tune`` and ``control`` steps: ``(fine-tuned policy spec, control policy spec or None)``."""
    from policies.training import resolve_checkpoint

    s, split = loop.settings, timed.steps.split
    excluded = set(split.held_out_scenarios) | set(split.held_out_family_names)
    for earlier in loop.state.rounds[:number - 1]:
        earlier_split = earlier.steps.split if earlier.steps.split is not None else SplitRecord()
        excluded.update(earlier_split.held_out_scenarios)
        excluded.update(earlier_split.held_out_family_names)
    arm = Arm(bank=loop.bank, method=s.fine_tune_method, steps=s.fine_tune_steps, seed=s.seed * 1000 + number,
              n_envs=s.n_envs, env_config=loop.env_config, fine_tune_config=loop.fine_tune_config,
              reward=s.fine_tune_reward, learning_rate=s.fine_tune_lr, beta_decay=s.dagger_beta_decay,
              progress=loop.progress, log=loop.log)
    if not timed.steps.done("fine_tune"):
        timed("fine_tune", lambda: fine_tune_arm(current, round_dir / "policy", excluded, s.mined_share, arm,
                                                 with_mined=True, label=f"round {number}"),
              f"{s.fine_tune_method} {s.fine_tune_steps} steps, the mined scenarios drawn with probability "
              f"{s.mined_share}")

    def spec_of(model: str, folder: Path) -> str:
        round_spec(f"ppo:{model}", folder, loop.out)  # loop.json is a file: only this round's own checkpoint
        return f"{resolve_checkpoint(model)[0]}:{model}"

    new_policy = spec_of(timed.steps.fine_tune.model, round_dir / "policy")
    loop.state.update(loop.state.round(number).replace(new_policy=new_policy), save=False)
    control_policy = None
    if s.control:
        if not timed.steps.done("control"):
            timed("control", lambda: fine_tune_arm(current, round_dir / "control", excluded, s.mined_share, arm,
                                                   with_mined=False, label=f"round {number} control"),
                  f"{s.fine_tune_method} {s.fine_tune_steps} steps without the mined scenarios")
        control_policy = spec_of(timed.steps.control.model, round_dir / "control")
        loop.state.update(loop.state.round(number).replace(control_policy=control_policy), save=False)
    return new_policy, control_policy


def _after_step(loop: RunningLoop, policies: Mapping[str, Optional[str]], episodes: List[tuple], store,
                families: Mapping[str, str]) -> HeldOutComparison:
    """The ``after`` step: start, fine-tuned and control on the held-out episodes, compared pairwise."""
    common = dict(store=store, bank_dir=loop.bank, env_config=loop.env_config,
                  workers=WorkerSettings(workers=loop.workers))
    before = heldout.evaluate_heldout("before", policies["before"], episodes, progress=False, **common)
    after = heldout.evaluate_heldout("after", policies["after"], episodes, progress=loop.progress, **common)
    control_records = None
    if policies["control"] is not None:
        control_records = heldout.evaluate_heldout("control", policies["control"], episodes, progress=loop.progress,
                                                   **common)
    s = loop.settings
    summary = heldout_comparison(before, after, control_records, min_episodes=s.min_heldout_episodes, seed=s.seed,
                                 families=families, min_families=s.min_heldout_families, margin=s.margin)
    return summary.replace(errored={
        "fine_tuned": errored_episodes(after),
        **({"control": errored_episodes(control_records)} if control_records is not None else {})})


def log_round(log: Callable[[str], None], number: int, steps: RoundSteps) -> None:
    """Log a measured round's outcome: the held-out failure rates (with the drop and the McNemar p-values, or why
    there are none), the untouched set's rates and the regression test's verdict."""
    after = steps.after

    if recorded(after):
        line = (f"round {number}: held-out failure rate start {rate_text(after.before)}, "
                + (f"control {rate_text(after.control)}, " if recorded(after.control) else "")
                + f"fine-tuned {rate_text(after.after)}")
        if after.underpowered:
            log(line + f"; NO DROP OR TEST REPORTED: {after.underpowered}")
        else:
            drop, versus = after.relative_drop, after.vs_control
            log(line + (f", relative drop {drop:.0%}" if drop is not None else "")
                + (f", McNemar p (two-sided) vs start = {after.mcnemar_p:.3g}" if after.mcnemar_p is not None else "")
                + (f", vs control = {versus.mcnemar_p:.3g}"
                   if versus is not None and versus.mcnemar_p is not None else ""))
    untouched = steps.untouched
    if recorded(untouched):
        def share(role: str) -> str:
            value = untouched.failure_rate(role)
            return "-" if value is None else f"{value:.2f}"

        vacuous = untouched.vacuous()
        log(f"round {number}: untouched set failure rate start {share('start')}, control {share('control')}, "
            f"fine-tuned {share('fine_tuned')}; fine-tuned vs start "
            f"{(untouched.fine_tuned_vs_start.verdict if untouched.fine_tuned_vs_start is not None else None)}"
            + (f"; WARNING: {vacuous}" if vacuous else ""))
    regress = steps.regress if steps.regress is not None else RegressSummary()
    log(f"round {number}: rest of the bank: {regress.verdict} ({regress.reason})")
