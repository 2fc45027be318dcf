"""A stand-in for the miner in loop tests: 'mines' by copying shipped scenarios into the bank as mined entries.

Each call writes a mining run folder in the miner's layout (``episodes.jsonl``,
``conversions.jsonl``) and adds one bank entry per fake cluster: a shipped script with a
comment line appended (a new content hash), provenance kind ``mined``. Resumable like the
real miner: a folder that already holds ``conversions.jsonl`` is left alone.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List, Sequence, Union

from dv2s_gym.loop import run as loop_module
from dv2s_gym.loop.record import LoopReportBody
from dv2s_gym.loop.settings import LoopSettings
from dv2s_gym.mining import miner as miner_module
from scenario_bank.atomic import atomic_write_json, atomic_write_text
from scenario_bank.bank import Bank, content_hash
from scenario_bank.records import HeldOutEpisode


def written_report(body: Union[Dict[str, Any], LoopReportBody]) -> LoopReportBody:
    """A loop report's ``body`` (its JSON object or record) with its recommendation, as the loop writes every
    ``report.json``; the settings the body does not give are the defaults, as ``loop.json`` records every
    setting."""
    from dv2s_gym.loop.settings import LoopSettings
    from dv2s_gym.loop.verdict import recommendation

    body = body.to_dict() if isinstance(body, LoopReportBody) else body
    report = LoopReportBody.from_dict({**body, "settings": {**LoopSettings().recorded(), **body.get("settings", {})}})
    return report.replace(recommendation=recommendation(report).to_dict())


def add_mined_copy(bank_dir: str, source: str, name: str, cluster: str, parent: str | None = None) -> str:
    """Copy shipped scenario ``source`` into ``bank_dir`` as entry ``name`` (kind ``mined``) whose provenance
    names ``parent`` (default ``source``) as the scenario it was mined from."""
    entry = Bank().get(source)
    script = entry.script + f"\n# mined copy for cluster {cluster}\n"
    meta = json.loads(json.dumps(entry.sidecar.to_dict()))
    meta.update(name=name, content_hash=content_hash(script))
    meta["source"] = {**meta["source"], "kind": "mined", "parent": parent or source, "seed": 0}
    folder = Path(bank_dir) / name
    folder.mkdir(parents=True)
    atomic_write_text(folder / "scenario.scenic", script)
    atomic_write_json(folder / "meta.json", meta)
    return name


class FakeMiner:
    """Callable with :func:`dv2s_gym.mining.miner.mine`'s signature; ``calls`` counts real work done (each call's
    settings and options)."""

    def __init__(self, sources: Sequence[str], failures_per_round: int = 6, replays: bool = False,
                 replays_only: bool = False) -> None:
        self.sources = list(sources)
        self.failures = failures_per_round
        self.replays = replays  # also an exact-replay entry per failure, as the real converter adds
        self.replays_only = replays_only  # every conversion rejected; the failures kept as replays.jsonl rows only
        self.calls: List[Dict[str, Any]] = []

    def __call__(self, policy: str, settings: Any, *, out: str, **options: Any):
        budget, bank_dir, seed = settings.budget, settings.bank_dir, settings.seed
        out_path = Path(out)
        if (out_path / "conversions.jsonl").is_file():
            return None
        self.calls.append({"policy": policy, "out": out, **settings.options(), **options})
        out_path.mkdir(parents=True, exist_ok=True)
        episodes, conversions, replayed = [], [], []
        for index in range(budget):
            source = self.sources[index % len(self.sources)]
            failed = index < self.failures
            episodes.append({"index": index, "scenario": source, "seed": 1000 + index, "params": {},
                             "failure": {"type": "collision"} if failed else None,
                             "avoidable": True if failed else None, "error": None})
            if failed and self.replays_only:
                cluster = f"{source}/collision/r{index}"
                replay = add_mined_copy(bank_dir, source, f"replay_s{seed}_{index}", cluster)
                replayed.append({"cluster": cluster, "index": index, "scenario": source, "status": "kept",
                                 "replay_entry": replay, "reason": None})
            elif failed:
                cluster = f"{source}/collision/r{index}"
                name = add_mined_copy(bank_dir, source, f"mined_s{seed}_{index}", cluster)
                replay = add_mined_copy(bank_dir, source, f"replay_s{seed}_{index}", cluster) if self.replays else None
                conversions.append({"cluster": cluster, "index": index, "status": "kept", "reason": None,
                                    "bank_entry": name, "replay_entry": replay, "reproduction": {"rate": 0.5}})
        (out_path / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in episodes))
        if replayed:
            (out_path / "replays.jsonl").write_text("".join(json.dumps(r) + "\n" for r in replayed))
        (out_path / "conversions.jsonl").write_text("".join(json.dumps(c) + "\n" for c in conversions))
        return None


def run_loop(policy: str = "dv2s-ppo", *, miner: Any = None, out: Any = loop_module.DEFAULT_OUT,
             progress: bool = True, log: Any = None, **settings: Any) -> "loop_module.LoopReport":
    """:func:`dv2s_gym.loop.run.run_loop` with its :class:`~dv2s_gym.loop.run.LoopSettings` as keywords (the
    tests' shorthand), mining with ``miner`` (a :class:`FakeMiner`) in place of the real miner when given."""
    from unittest import mock

    options = {"out": out, "progress": progress, **({"log": log} if log is not None else {})}
    loop_settings = LoopSettings(**settings)
    if miner is None:
        return loop_module.run_loop(policy, loop_settings, **options)
    with mock.patch.object(miner_module, "mine", miner):
        return loop_module.run_loop(policy, loop_settings, **options)


def held(rows: Any) -> Any:
    """Held-out rows (``{"scenario", "seed", "failed", "error"...}``) as the held-out store's records
    (:class:`~scenario_bank.records.HeldOutEpisode`, role ``before`` unless a row names one); ``None`` stays
    ``None``."""
    if rows is None:
        return None
    return [HeldOutEpisode.from_dict({"role": "before", **row}) for row in rows]
