"""Model cards: what a trained checkpoint is, how it was made and how it scores.

A card is ``model_card.json`` beside the checkpoint's ``model.zip`` (the registry reads
its ``algorithm`` to load the zip), with a human-readable ``README.md`` rendered from it.
It records the algorithm, hyperparameters, env config, the bank version (a content
hash of the scenarios trained on) and scenario list, steps, seed, wall time, the
command that reproduces it, and an evaluation on held-out episodes:

- ``evaluation.episodes``: the ``(scenario, seed)`` pairs, every scenario with the
  seeds ``seed_base .. seed_base + seeds - 1`` (never used in training, see
  :data:`policies.evaluation.EVAL_SEED_BASE`);
- ``evaluation.policies[label]``: for the trained policy (label ``"policy"``) and each
  baseline, overall and per-scenario collision, success, off-road and failure rates,
  each ``{"k", "n", "rate", "lo", "hi"}`` with a Wilson interval, and the outcome of
  every episode as one character (:func:`outcome_code`), so the paired comparisons can
  be recomputed and a re-run can be checked episode by episode;
- ``evaluation.comparisons[baseline][measure]``: the paired table against a baseline
  and exact McNemar p-values (two-sided and one-sided "the policy is lower");
- ``evaluation.summary``: plain sentences saying where the policy beats each baseline
  and where it does not.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union
import multiprocessing
import signal
import time

from tqdm import tqdm

from envs.errors import DV2SError
from policies.card_record import CardEvaluation, CardOverall, CardResults, ModelCard
from policies.evaluation import EpisodeResult, evaluate
from policies.stats import Rate, mcnemar_p
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.catalog import open_bank
from scenario_bank.records import RecordError

__all__ = [
    "CARD_NAME",
    "README_NAME",
    "CARD_VERSION",
    "MEASURES",
    "ModelCardError",
    "bank_version",
    "outcome_code",
    "rate",
    "summarize_results",
    "compare_paired",
    "evaluation_section",
    "TimeLeft",
    "summary_sentences",
    "write_card",
    "read_card",
    "render_markdown",
    "evaluate_parallel",
    "evaluate_for_card",
]

CARD_NAME = "model_card.json"
README_NAME = "README.md"
CARD_VERSION = 1

MEASURES = ("collision", "success", "off_road", "failure")
"""Per-episode events a card reports a rate for (``failure`` = collision or off-road)."""

_LOWER_IS_BETTER = {"collision": True, "off_road": True, "failure": True, "success": False}


class ModelCardError(DV2SError, ValueError):
    """A model card that is missing, unreadable or not a dv2s-gym card."""


# --------------------------------------------------------------------------- bank version
def bank_version(names: Sequence[str], bank_dir: Optional[Union[str, os.PathLike]] = None) -> Dict[str, Any]:
    """The content hash of the scenarios ``names``: SHA-256 over their sorted names and script hashes.

    Returns ``{"version": hex, "scenarios": {name: content_hash}}``; the version changes
    when a scenario is added, removed or its script edited.
    """
    bank = open_bank(bank_dir)
    hashes = {name: bank.get(name).content_hash for name in sorted(set(names))}
    payload = json.dumps(sorted(hashes.items()), separators=(",", ":"))
    return {"version": hashlib.sha256(payload.encode("utf-8")).hexdigest(), "scenarios": hashes}


# --------------------------------------------------------------------------- rates
def rate(k: int, n: int, confidence: float = 0.95) -> Rate:
    """``k`` events in ``n`` episodes with a Wilson interval (:meth:`policies.stats.Rate.of`); a card's rate without
    an episode is 0.0. The card writes it as ``{"k", "n", "rate", "lo", "hi"}``."""
    found = Rate.of(k, n, confidence)
    return found if n else found.replace(rate=0.0)


def _card_json(found: Rate) -> Dict[str, Any]:
    """A rate as the card's JSON object names it: ``{"k", "n", "rate", "lo", "hi"}``."""
    return {"k": found.k, "n": found.n, "rate": found.rate, "lo": found.low, "hi": found.high}


def _card_rate(data: Mapping[str, Any]) -> Rate:
    """The rate of a card's JSON object (:func:`_card_json`)."""
    return Rate(k=data["k"], n=data["n"], rate=data["rate"], low=data["lo"], high=data["hi"])


def outcome_code(result: EpisodeResult) -> str:
    """One character per episode: ``C`` collision, ``O`` off the road (no collision),
    ``S`` success, ``-`` neither (the ego stalled short of the success distance), ``E`` error."""
    if result.error is not None:
        return "E"
    if result.collided:
        return "C"
    if result.off_road:
        return "O"
    return "S" if result.success else "-"


def _events(code: str) -> Dict[str, bool]:
    return {"collision": code == "C", "off_road": code == "O", "failure": code in "CO", "success": code == "S"}


def _rates_of(codes: str, confidence: float) -> Dict[str, Any]:
    valid = [c for c in codes if c != "E"]
    return {measure: _card_json(rate(sum(_events(c)[measure] for c in valid), len(valid), confidence))
            for measure in MEASURES}


def summarize_results(results: Sequence[EpisodeResult], confidence: float = 0.95) -> CardResults:
    """Overall and per-scenario rates of ``results`` plus every episode's outcome code.

    Episodes that ended in an error are excluded from the rates and counted under ``errors``.
    """
    outcomes: Dict[str, str] = {}
    for result in results:
        outcomes[result.scenario] = outcomes.get(result.scenario, "") + outcome_code(result)
    every = "".join(outcomes[name] for name in sorted(outcomes))
    valid = [r for r in results if r.error is None]
    overall = CardOverall(**_rates_of(every, confidence), episodes=len(results), errors=every.count("E"),
                          mean_return=sum(r.episode_return for r in valid) / len(valid) if valid else 0.0,
                          mean_speed=sum(r.mean_speed for r in valid) / len(valid) if valid else 0.0)
    return CardResults(overall=overall,
                       per_scenario={name: _rates_of(outcomes[name], confidence) for name in sorted(outcomes)},
                       outcomes={name: outcomes[name] for name in sorted(outcomes)})


def compare_paired(candidate_codes: str, baseline_codes: str, measure: str = "collision") -> Dict[str, Any]:
    """Paired comparison of two policies' outcome codes on the same episodes for one measure.

    Returns the table of the measure's event (``both``, ``candidate_only``,
    ``baseline_only``, ``neither``), both rates and exact McNemar p-values:
    ``p_two_sided`` and ``p_candidate_better`` (one-sided: the candidate has the event less
    often, or for ``success`` more often). Episodes where either policy hit an error are
    left out.
    """
    if len(candidate_codes) != len(baseline_codes):
        raise ModelCardError(f"paired comparison needs the same episodes: {len(candidate_codes)} outcomes "
                             f"against {len(baseline_codes)}")
    pairs = [(a, b) for a, b in zip(candidate_codes, baseline_codes) if a != "E" and b != "E"]
    candidate = [_events(a)[measure] for a, _ in pairs]
    baseline = [_events(b)[measure] for _, b in pairs]
    lower_better = _LOWER_IS_BETTER[measure]
    n = len(pairs)
    both = sum(a and b for a, b in zip(candidate, baseline))
    candidate_only = sum(a and not b for a, b in zip(candidate, baseline))
    baseline_only = sum(b and not a for a, b in zip(candidate, baseline))
    return {
        "measure": measure,
        "n": n,
        "candidate_rate": sum(candidate) / n if n else 0.0,
        "baseline_rate": sum(baseline) / n if n else 0.0,
        "table": {"both": both, "candidate_only": candidate_only, "baseline_only": baseline_only,
                  "neither": n - both - candidate_only - baseline_only},
        "p_two_sided": mcnemar_p(candidate_only, baseline_only, "two-sided"),
        # better: fewer collisions / off-road / failures, or more successes
        "p_candidate_better": mcnemar_p(candidate_only, baseline_only, "less" if lower_better else "greater"),
        "p_candidate_worse": mcnemar_p(candidate_only, baseline_only, "greater" if lower_better else "less"),
    }


def evaluation_section(results: Mapping[str, Sequence[EpisodeResult]], episodes: Sequence[Tuple[str, int]],
                       candidate: str = "policy", confidence: float = 0.95, alpha: float = 0.05,
                       seed_base: Optional[int] = None, seeds: Optional[int] = None,
                       specs: Optional[Mapping[str, str]] = None) -> CardEvaluation:
    """The card's ``evaluation``: rates per policy, paired comparisons of ``candidate``
    against every other label, and the summary sentences."""
    episodes = [(str(s), int(seed)) for s, seed in episodes]
    for label, rows in results.items():
        if [(r.scenario, r.seed) for r in rows] != episodes:
            raise ModelCardError(f"results of {label!r} are not the card's episodes in order")
    policies = {label: summarize_results(rows, confidence) for label, rows in results.items()}
    codes = {label: "".join(data.outcomes[name] for name in sorted(data.outcomes)) for label, data in policies.items()}
    section = CardEvaluation(
        confidence=confidence, interval="wilson", alpha=alpha, candidate=candidate, episodes_total=len(episodes),
        scenarios=tuple(sorted({s for s, _ in episodes})), seed_base=seed_base, seeds_per_scenario=seeds,
        specs=dict(specs or {}), policies=policies,
        comparisons={label: {measure: compare_paired(codes[candidate], codes[label], measure) for measure in MEASURES}
                     for label in results if label != candidate})
    return section.replace(summary=tuple(summary_sentences(section)))


def _fmt(r: Mapping[str, Any]) -> str:
    return _card_rate(r).text(3, counts=False)


def summary_sentences(section: CardEvaluation) -> List[str]:
    """Plain sentences: for each baseline and measure whether the candidate is significantly
    better, significantly worse, or not distinguishable, and the scenarios where it is worse."""
    candidate = section.candidate
    alpha = section.alpha if section.alpha is not None else 0.05
    mine = section.policies[candidate]
    sentences = []
    for label, comparisons in (section.comparisons or {}).items():
        theirs = section.policies[label]
        for measure in ("collision", "success", "failure"):
            c = comparisons[measure]
            lower_better = _LOWER_IS_BETTER[measure]
            ours, base = _fmt(mine.overall.measure(measure)), _fmt(theirs.overall.measure(measure))
            p_better = c["p_candidate_better"]
            worse_count = c["table"]["candidate_only"] if lower_better else c["table"]["baseline_only"]
            better_count = c["table"]["baseline_only"] if lower_better else c["table"]["candidate_only"]
            if p_better < alpha:
                verdict = "beats"
            elif c["p_candidate_worse"] < alpha:
                verdict = "does NOT beat (it is significantly worse than)"
            else:
                verdict = "is not distinguishable from"
            sentences.append(
                f"On {measure} rate the {candidate} {verdict} {label}: {ours} against {base} "
                f"(paired exact McNemar, {better_count} episodes better, {worse_count} worse, "
                f"one-sided p={p_better:.3g}, two-sided p={c['p_two_sided']:.3g}).")
        worse = []
        for name, rates in mine.per_scenario.items():
            base_rates = theirs.per_scenario[name]
            if rates["collision"]["k"] > base_rates["collision"]["k"]:
                worse.append(f"{name} ({rates['collision']['k']}/{rates['collision']['n']} collisions "
                             f"against {base_rates['collision']['k']}/{base_rates['collision']['n']})")
        if worse:
            sentences.append(f"The {candidate} collides more often than {label} on {len(worse)} scenario(s): "
                             + "; ".join(worse) + ".")
        else:
            sentences.append(f"The {candidate} collides no more often than {label} on any scenario.")
    return sentences


# --------------------------------------------------------------------------- files
def _card_path(location: Union[str, os.PathLike]) -> Path:
    path = Path(location)
    if path.suffix == ".json":
        return path
    return (path.parent if path.suffix == ".zip" else path) / CARD_NAME


def write_card(directory: Union[str, os.PathLike], card: ModelCard) -> Path:
    """Write ``card`` as ``model_card.json`` and its rendering as ``README.md`` in
    ``directory`` (both atomic); returns the JSON path."""
    directory = Path(directory)
    data = json.loads(json.dumps({"card_version": CARD_VERSION, **card.to_dict()}, default=str, sort_keys=True))
    path = atomic_write_json(directory / CARD_NAME, data, indent=1)
    # the same text read_card + render gives
    atomic_write_text(directory / README_NAME, render_markdown(ModelCard.from_dict(data)))
    return path


def read_card(location: Union[str, os.PathLike]) -> ModelCard:
    """The card at ``location``: a card file, the folder holding it, or the ``model.zip`` beside it."""
    path = _card_path(location)
    if not path.is_file():
        raise ModelCardError(f"no model card at {path}; train with `dv2s train`, which writes one beside model.zip")
    try:
        card = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise ModelCardError(f"model card {path} is not readable JSON ({error}); fix it or re-run `dv2s train`") from error
    if not isinstance(card, dict) or "algorithm" not in card:
        raise ModelCardError(f"{path} is not a dv2s-gym model card (no 'algorithm'); re-run `dv2s train`")
    try:
        record = ModelCard.from_dict(card)
    except RecordError as error:
        raise ModelCardError(f"model card {path}: {error}; fix it or re-run `dv2s train`") from error
    if (record.card_version or 0) > CARD_VERSION:
        raise ModelCardError(f"model card {path} has version {record.card_version}, newer than this "
                             f"dv2s-gym reads ({CARD_VERSION}); upgrade dv2s-gym")
    return record


def _rate_cell(r: Mapping[str, Any]) -> str:
    return _card_rate(r).text(2)


def render_markdown(card: ModelCard) -> str:
    """A human-readable rendering of a card (the ``README.md`` beside it)."""
    training = card.training or {}
    bank = card.bank or {}
    lines = [f"# {card.name or 'model'} — {str(card.algorithm or '').upper()} on DV2S-v0", ""]
    if card.description:
        lines += [card.description, ""]
    lines += [
        "Written by `dv2s train` from `model_card.json` (the data; this file is its rendering).", "",
        "## Training", "",
        f"- command: `{training.get('command', '')}` (its `--out` folder then holds model.zip and this card)",
        f"- steps: {training.get('steps')} ({training.get('n_envs')} subprocess envs), seed {training.get('seed')}",
        f"- wall time: {training.get('wall_time_s', 0):.0f} s ({training.get('steps_per_s', 0):.0f} env steps/s)",
        f"- scenario sampling: {(card.sampler or {}).get('mode')}",
        f"- bank version: `{bank.get('version', '')}` ({len(bank.get('scenarios', {}))} scenarios)",
        f"- hyperparameters: `{json.dumps(dict(card.hyperparameters or {}), sort_keys=True)}`",
        f"- env config overrides: `{json.dumps(dict(card.env_config or {}), sort_keys=True)}`",
        f"- spaces: observation {card.observation_space}, action {card.action_space}",
        "",
    ]
    evaluation = card.evaluation
    if card.evaluation_interrupted:
        command = str(training.get("command") or "dv2s train --out FOLDER")
        resume = command if "--resume" in command.split() else f"{command} --resume"
        lines += ["## Evaluation", "",
                  "**Not evaluated: the held-out evaluation was interrupted before it finished.** Complete it with "
                  f"`{resume}`: the trained model is kept and only the evaluation runs.", ""]
    if evaluation is not None and evaluation.to_dict():
        lines += _evaluation_lines(evaluation)
    return "\n".join(lines) + "\n"


def _evaluation_lines(evaluation: CardEvaluation) -> List[str]:
    """The rendering's evaluation: the overall rates per policy, the summary and the per-scenario rates."""
    confidence = evaluation.confidence if evaluation.confidence is not None else 0.95
    seed_base, seeds = evaluation.seed_base, evaluation.seeds_per_scenario
    scenarios = evaluation.scenarios or ()
    lines = [
        "## Evaluation", "",
        f"{evaluation.episodes_total} held-out episodes: {len(scenarios)} scenarios x "
        f"seeds {seed_base}..{(seed_base or 0) + (seeds or 0) - 1}"
        f" (never used in training). Rates with Wilson {confidence:.0%} intervals.", "",
        "| policy | collision | success | off-road | failure |", "|---|---|---|---|---|",
    ]
    policies = evaluation.policies or {}
    labels = [evaluation.candidate] + sorted(set(policies) - {evaluation.candidate})
    for label in labels:
        o = policies[label].overall
        lines.append(f"| {label} | {_rate_cell(o.collision)} | {_rate_cell(o.success)} | "
                     f"{_rate_cell(o.off_road)} | {_rate_cell(o.failure)} |")
    lines += ["", "### Summary", ""] + [f"- {s}" for s in evaluation.summary or ()]
    for measure, title in (("collision", "collision rate"), ("success", "success rate")):
        lines += ["", f"### Per scenario ({title})", "",
                  "| scenario | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
        for name in scenarios:
            cells = [_rate_cell(policies[label].per_scenario[name][measure]) for label in labels]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _evaluate_chunk(spec: str, episodes: List[Tuple[str, int]], config: Optional[Dict[str, Any]],
                    bank_dir: Optional[str]) -> List[EpisodeResult]:
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    torch.set_num_threads(1)
    return evaluate(spec, episodes, config=config, bank_dir=bank_dir)


def evaluate_parallel(spec: str, episodes: Sequence[Tuple[str, int]], config: Optional[Dict[str, Any]] = None,
                      bank_dir: Optional[str] = None, jobs: int = 2,
                      on_done: Optional[Callable[[int], None]] = None) -> List[EpisodeResult]:
    """:func:`policies.evaluation.evaluate` of a policy spec over ``episodes`` in ``jobs`` processes.

    Episodes go to the processes in small consecutive chunks and the results come back in the
    order of ``episodes``; an episode's result does not depend on the process it ran in.
    ``on_done(n)`` is called as chunks of ``n`` episodes finish (a progress bar). On an interrupt
    the worker processes are terminated at once, not waited for.
    """
    episodes = [(str(s), int(seed)) for s, seed in episodes]
    jobs = max(1, min(int(jobs), len(episodes)))
    size = max(1, min(25, len(episodes) // (jobs * 4) or 1))
    chunks = [episodes[i:i + size] for i in range(0, len(episodes), size)]
    results: List[EpisodeResult] = []
    if jobs == 1:
        for chunk in chunks:
            results += _evaluate_chunk(spec, chunk, config, bank_dir)
            if on_done is not None:
                on_done(len(chunk))
        return results

    # workers leave Ctrl-C to this process, which stops them: one line to the user, no worker tracebacks
    pool = multiprocessing.get_context("forkserver").Pool(jobs, initializer=_ignore_interrupts)
    try:
        for part in pool.imap(_evaluate_chunk_args, [(spec, chunk, config, bank_dir) for chunk in chunks]):
            results += part
            if on_done is not None:
                on_done(len(part))
        pool.close()
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()
    return results


def _ignore_interrupts() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _evaluate_chunk_args(args: Tuple[str, List[Tuple[str, int]], Optional[Dict[str, Any]], Optional[str]]
                         ) -> List[EpisodeResult]:
    return _evaluate_chunk(*args)


class TimeLeft:
    """Says once, in one line, how long a run of ``total`` episodes has left: when a twentieth of them (at least
    ten) are done, from their pace (it includes the workers' start-up, so the estimate errs long)."""

    def __init__(self, total: int, log: Callable[[str], None], what: str) -> None:
        self.total, self.log, self.what = int(total), log, what
        self.done, self.said, self.began = 0, False, time.perf_counter()

    def update(self, count: int) -> None:
        """``count`` more episodes are done."""
        self.done += int(count)
        if self.said or self.done >= self.total or self.done < min(self.total, max(10, self.total // 20)):
            return
        self.said = True
        elapsed = time.perf_counter() - self.began
        left = elapsed / self.done * (self.total - self.done)
        self.log(f"{self.what}: {self.done} of {self.total} episodes in {_duration(elapsed)}; about "
                 f"{_duration(left)} left")


def _duration(seconds: float) -> str:
    """``seconds`` for people: ``45 s``, ``12 min``, ``1 h 05 min``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


def evaluate_for_card(specs: Mapping[str, str], episodes: Sequence[Tuple[str, int]],
                      configs: Mapping[str, Optional[Dict[str, Any]]], bank_dir: Optional[str] = None,
                      jobs: int = 2, progress: bool = False, log: Optional[Callable[[str], None]] = None,
                      **section: Any) -> CardEvaluation:
    """Run every policy of ``specs`` (label -> spec) on the same ``episodes`` and build the
    card's ``evaluation`` section (:func:`evaluation_section`, which takes ``section``: ``candidate``,
    ``confidence``, ``seed_base``, ``seeds``); ``configs`` gives each
    label's env config (a baseline driving ``DiscreteMetaAction`` next to a continuous policy).
    ``progress``: one progress bar on stderr over every policy's episodes; ``log``: gets one line with the
    time left, estimated once the first episodes are done (:class:`TimeLeft`)."""
    total = len(specs) * len(episodes)
    bar = None
    if progress:
        bar = tqdm(total=total, desc="card evaluation", unit="episode", file=sys.stderr, dynamic_ncols=True)
    time_left = TimeLeft(total, log, "model card evaluation") if log is not None else None

    def on_done(count: int) -> None:
        if bar is not None:
            bar.update(count)
        if time_left is not None:
            time_left.update(count)

    try:
        results = {label: evaluate_parallel(spec, episodes, configs.get(label), bank_dir, jobs, on_done=on_done)
                   for label, spec in specs.items()}
    finally:
        if bar is not None:
            bar.close()
    return evaluation_section(results, episodes, specs=specs, **section)
