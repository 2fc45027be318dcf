"""Story rate: how often a bank scenario plays its adversarial story, whatever the ego does.

A scenario whose sidecar has a ``story`` block (its story actors by script name, and the steps
each must play) is checked actor by actor by :func:`dv2s_gym.story_check.check_story`: every
step of every story actor, bound to that actor, relations read at the moment of the step's event,
timing where the step asks for it. The rest of this docstring describes the older, kind-based
check that sidecars without a ``story`` block get.

An episode *plays its story* when the elements read off its trace
(:func:`dv2s_gym.pipeline.semantics.trace.elements_from_trace`) contain every
action and every relation of the scenario's sidecar whose subject is not the ego:
the adversaries' story relative to the ego (the cut-in car cuts in, the oncoming
car goes straight and crosses the ego's path, the pedestrian crosses...). The
ego's own sidecar actions (``ego turn_left``...) are required only for the
``scenic`` ego, which drives the script's own ego behaviour; the other egos drive
their own way and cannot be asked to play the ego's part. Participants and road
type are not checked (they hold by construction). A collision of the ego with an
actor of a kind that has a part in the story (a car when ``car go_straight`` is
required) counts as the story played: the encounter happened and the crash ended
it before the rest could be seen (the episode ends on a collision).

Egos (:data:`EGOS`): ``scenic`` (the script's ego behaviour), ``rule``
(:class:`policies.rule_based.CautiousDriver`), ``keep_lane``
(:class:`policies.baselines.KeepLaneEgo`, constant speed) and ``idm``
(:class:`policies.baselines.IDMEgo`). Episodes use the env's default duration
unless the scenario needs longer (:data:`STORY_SECONDS`).

Probe egos (:data:`PROBE_EGOS`, selectable by name, not part of the :data:`EGOS` the 90% contract is
stated on) drive unlike traffic on purpose, to check that a scenario's actors adapt to the ego:
``hangback``, ``rush``, ``surge`` and ``weave`` (:mod:`policies.probe_drivers`).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from tqdm import tqdm

from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from dv2s_gym.story_check import check_story
from policies.baselines import IDMEgo, KeepLaneEgo
from policies.probe_drivers import HangbackEgo, RushEgo, SurgeEgo, WeaveEgo
from scenario_bank.bank import Bank
from scenario_bank.elements import Elements
from scenario_bank.errors import DV2SError, UnknownScenarioError
from scenario_bank.story import normalize_story

__all__ = ["EGOS", "PROBE_EGOS", "ALL_EGOS", "STORY_SECONDS", "required_elements", "story_problem", "ego_collisions", "run_episode",
           "story_episodes", "missed_steps", "story_rate", "story_table", "UnknownEgoError", "StoryCheck", "check_stories"]

EGOS = ("scenic", "rule", "keep_lane", "idm")
"""Ego drivers a story is checked against."""

PROBE_EGOS: Dict[str, str] = {
    "hangback": "drives at 60% of its start speed and keeps a 3 s gap (policies.probe_drivers.HangbackEgo)",
    "rush": "asks FASTER from the first step until its target is 10 m/s above its start speed (policies.probe_drivers.RushEgo)",
    "surge": "holds its start speed, then at 3 s raises its target by 10 m/s (policies.probe_drivers.SurgeEgo)",
    "weave": "changes lanes left and right every 3 s from 1 s on (policies.probe_drivers.WeaveEgo)",
}
"""Extra egos that probe how a scenario's actors adapt to the ego, by name, with how each drives."""

ALL_EGOS = EGOS + tuple(PROBE_EGOS)
"""Every ego name :func:`story_table` and :func:`run_episode` accept."""



class UnknownEgoError(DV2SError, ValueError):
    """An ego name that is not one of :data:`ALL_EGOS`; the message lists them."""


def _check_egos(egos: Sequence[str]) -> None:
    unknown = [e for e in egos if e not in ALL_EGOS]
    if unknown:
        raise UnknownEgoError(f"unknown ego {unknown[0]!r}; choose from {', '.join(ALL_EGOS)}")


STORY_SECONDS: Dict[str, float] = {}
"""Episode lengths that differ from the env's default duration, per scenario."""


def required_elements(elements: Elements, ego: str) -> set:
    """The ``(kind, action)`` and ``(kind, relation, other)`` tuples an episode with ``ego`` must show."""
    required = {a for a in elements.actions if ego == "scenic" or a[0] != "ego"}
    required |= {r for r in elements.relations if r[0] != "ego"}
    return required


def story_problem(elements: Elements, shown: Elements, ego: str,
                  ego_hit: Sequence[str] = ()) -> Optional[str]:
    """What of the story an episode that shows ``shown`` misses; None when it plays the story.

    ``ego_hit``: kinds of the actors the ego collided with.
    """
    required = required_elements(elements, ego)
    if set(ego_hit) & {r[0] for r in required if r[0] != "ego"}:
        return None
    have = set(shown.actions) | set(shown.relations)
    missing = sorted(required - have)
    return ("missing " + ", ".join(" ".join(map(str, m)) for m in missing)) if missing else None


def ego_collisions(trace) -> List[str]:
    """Kinds (car, truck, pedestrian, obstacle...) of the actors the ego collided with in ``trace``."""
    kinds = dict(getattr(trace, "kinds", {}) or {})
    hit = []
    for event in trace.events:
        actors = event.get("actors") or []
        if event.get("kind") == "collision" and "ego" in actors:
            for actor in actors:
                if actor != "ego":
                    hit.append(kinds.get(actor) or _kind_of(actor))
    return hit


def _kind_of(name: str) -> str:
    lowered = name.lower()
    for word, kind in (("pedestrian", "pedestrian"), ("truck", "truck"), ("obstacle", "obstacle"),
                       ("prop", "obstacle")):
        if word in lowered:
            return kind
    return "car"


def _driver(ego: str, env) -> Callable[[], int]:
    from policies.rule_based import IDLE, CautiousDriver

    if ego == "scenic":
        return lambda: IDLE  # ignored: the script's behaviour drives the ego
    drivers = {"rule": CautiousDriver, "keep_lane": KeepLaneEgo, "idm": IDMEgo,
               "hangback": HangbackEgo, "rush": RushEgo, "surge": SurgeEgo, "weave": WeaveEgo}
    if ego not in drivers:
        _check_egos([ego])
    return drivers[ego](env).act


def run_episode(script_path: str, ego: str, seed: int, seconds: Optional[float] = None):
    """One DV2S-v0 episode of a scenario with the given ego; returns its trace."""
    from envs.dv2s_env import DV2SEnv

    config: Dict[str, Any] = {"ego_policy": "scenic" if ego == "scenic" else "agent"}
    if seconds is not None:
        config["duration"] = seconds
    env = DV2SEnv(scenario=script_path, config=config)
    try:
        env.reset(seed=seed)
        act = _driver(ego, env)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(act())
            done = terminated or truncated
        return env.trace
    finally:
        env.close()


def story_episodes(name: str, ego: str, seeds: Sequence[int], bank_root: Optional[str] = None
                   ) -> List[Dict[str, Any]]:
    """Per seed: ``{"seed", "problem", "missing", "missed", "ego_hit"}`` for bank scenario ``name`` with ``ego``.

    ``problem`` is None when the episode plays the story; ``missing`` is what its trace lacks when a
    collision is not counted as the story (None when nothing is missing); ``missed`` the ``[step, why]``
    pairs of the steps it did not play (a sidecar without a ``story`` block: ``[what is missing, ""]``);
    ``ego_hit`` the kinds the ego hit.
    """
    entry = Bank(bank_root).get(name)
    story = entry.sidecar.story
    story = normalize_story(story, f"{name}: story") if story is not None else None
    elements = entry.elements
    seconds = STORY_SECONDS.get(name)
    records = []
    for seed in seeds:
        trace = run_episode(str(entry.script_path), ego, seed, seconds)
        hit = ego_collisions(trace)
        if story is not None:
            result = check_story(story, trace, ego)
            records.append({"seed": seed, "problem": result.problem(),
                            "missing": "; ".join(result.by_collision) or result.problem(),
                            "missed": [list(m) for m in result.missed], "ego_hit": hit})
            continue
        shown = elements_from_trace(trace)
        problem = story_problem(elements, shown, ego, hit)
        records.append({"seed": seed, "problem": problem, "missing": story_problem(elements, shown, ego),
                        "missed": [[problem, ""]] if problem else [], "ego_hit": hit})
    return records


def missed_steps(records: Sequence[Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """Per step missed in ``records`` (of :func:`story_episodes`): ``{"count", "seed", "why"}``, the seed and
    reason of its first miss, so a scenario author can replay one episode that shows it."""
    out: Dict[str, Dict[str, Any]] = {}
    for record in records:
        for step, why in record.get("missed", []):
            if step not in out:
                out[step] = {"count": 0, "seed": record["seed"], "why": why}
            out[step]["count"] += 1
    return out


def story_rate(name: str, ego: str, seeds: Sequence[int], bank_root: Optional[str] = None
               ) -> Tuple[float, List[Tuple[int, str]]]:
    """Share of ``seeds`` whose episode plays the story of bank scenario ``name`` with ``ego``.

    Returns ``(rate, failures)``, ``failures`` a list of ``(seed, what was missing)``.
    """
    records = story_episodes(name, ego, seeds, bank_root)
    failures = [(r["seed"], r["problem"]) for r in records if r["problem"]]
    return (1.0 - len(failures) / len(records)) if records else 0.0, failures


def _rate_job(args) -> Tuple[str, str, Dict[str, Any]]:
    name, ego, seeds, bank_root = args
    try:
        records = story_episodes(name, ego, seeds, bank_root)
    except Exception as error:  # a scenario that does not run has no story
        problem = f"{type(error).__name__}: {error}"
        return name, ego, {"rate": 0.0, "failures": [(-1, problem)], "by_collision": 0,
                           "missed": {"the scenario runs": {"count": len(seeds), "seed": -1, "why": problem}}}
    failures = [(r["seed"], r["problem"]) for r in records if r["problem"]]
    by_collision = sum(1 for r in records if r["problem"] is None and r["missing"])
    return name, ego, {"rate": 1.0 - len(failures) / len(records) if records else 0.0, "failures": failures,
                       "by_collision": by_collision, "missed": missed_steps(records)}


def story_table(names: Sequence[str], egos: Sequence[str] = EGOS, seeds: Sequence[int] = range(20),
                bank_root: Optional[str] = None, jobs: int = 1, progress: bool = True
                ) -> Dict[str, Dict[str, Dict[str, Any]]]:
    """``{scenario: {ego: {"rate", "failures", "by_collision", "missed"}}}`` over ``seeds``, in ``jobs`` processes.

    ``by_collision``: episodes counted as playing the story because the ego hit a story actor
    before the trace showed all of it; ``missed``: per step not played, how often, the first seed that
    missed it and why (:func:`missed_steps`).
    """
    _check_egos(egos)
    tasks = [(n, e, list(seeds), bank_root) for n in names for e in egos]
    table: Dict[str, Dict[str, Dict[str, Any]]] = {n: {} for n in names}
    bar = tqdm(total=len(tasks), desc="story rate", unit="run", disable=not progress)
    if jobs <= 1:
        results = map(_rate_job, tasks)
    else:
        pool = ProcessPoolExecutor(max_workers=jobs)
        results = pool.map(_rate_job, tasks)
    for name, ego, cell in results:
        table[name][ego] = cell
        bar.update()
    if jobs > 1:
        pool.shutdown()
    bar.close()
    return table


@dataclass
class StoryCheck:
    """The story rates of scenarios (:func:`check_stories`): ``table`` as :func:`story_table` gives it and the
    scenarios with a rate under ``threshold`` for some ego (``under``)."""

    names: List[str]
    egos: List[str]
    seeds: int
    threshold: float
    table: Dict[str, Dict[str, Dict[str, Any]]]
    under: List[str]

    @property
    def ok(self) -> bool:
        """Whether every scenario plays its story at least at the threshold rate with every ego."""
        return not self.under

    def as_dict(self) -> Dict[str, Any]:
        return {"seeds": self.seeds, "threshold": self.threshold, "egos": self.egos, "table": self.table,
                "under_threshold": self.under}


def check_stories(names: Sequence[str] = (), egos: Sequence[str] = EGOS, seeds: int = 20, threshold: float = 0.9,
                  bank_root: Optional[str] = None, jobs: int = 1, progress: bool = True) -> StoryCheck:
    """The story rate of the bank's scenarios ``names`` (all by default) with each of ``egos`` over ``seeds`` seeds,
    and which are under ``threshold``. A name the bank does not hold is an :class:`UnknownScenarioError`, an ego
    that does not exist an :class:`UnknownEgoError`, both before any episode runs."""
    known = Bank(bank_root).names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UnknownScenarioError(f"unknown scenario {unknown[0]!r} in the bank; `dv2s bank list` shows its "
                                   "scenarios")
    _check_egos(egos)
    names = list(names) or known
    table = story_table(names, egos, range(seeds), bank_root=bank_root, jobs=jobs, progress=progress)
    under = sorted(n for n, row in table.items() if any(cell["rate"] < threshold for cell in row.values()))
    return StoryCheck(names, list(egos), seeds, threshold, table, under)
