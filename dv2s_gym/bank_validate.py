"""``dv2s bank validate``: check that every bank entry is safe, compiles, samples and runs."""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional, Sequence

from tqdm import tqdm

from scenario_bank.bank import Bank, content_hash
from scenario_bank.sandbox import check_in_jail
from scenario_bank.shipped import is_shipped_text
from scenario_bank.maps import list_maps

__all__ = ["EntryReport", "validate_entry", "validate_bank"]


@dataclass
class EntryReport:
    """Validation of one bank entry."""

    name: str
    ok: bool = False
    safety: List[str] = field(default_factory=list)
    sidecar: List[str] = field(default_factory=list)
    compile_seconds: Optional[float] = None
    samples: int = 0
    sampling_iterations: int = 0
    episodes: List[Dict[str, Any]] = field(default_factory=list)
    error: Optional[str] = None

    @property
    def acceptance_rate(self) -> Optional[float]:
        """Accepted scenes per rejection-sampling iteration."""
        return self.samples / self.sampling_iterations if self.sampling_iterations else None

    def as_dict(self) -> Dict[str, Any]:
        data = asdict(self)
        data["acceptance_rate"] = self.acceptance_rate
        return data


def _outcome(info: Dict[str, Any], terminated: bool, truncated: bool) -> str:
    if info.get("crashed"):
        return "collision:" + ",".join(info.get("collisions", []))
    if info.get("off_road"):
        return "off_road"
    if info.get("scenic_status") in ("finished", "rejected"):
        return "scenic_" + info["scenic_status"]
    return "time_limit" if truncated else ("terminated" if terminated else "running")


def validate_entry(bank_root: Optional[str], name: str, samples: int = 3, seconds: float = 3.0) -> EntryReport:
    """Safety check, sidecar check, compile, sample ``samples`` scenes, run each ``seconds`` in DV2S-v0."""
    from envs.dv2s_env import DV2SEnv, ScenarioRef

    report = EntryReport(name)
    try:
        entry = Bank(bank_root).get(name)
        script = entry.script
        report.safety = [] if is_shipped_text(script) else [str(f) for f in check_in_jail(script, name=name)]
        if entry.content_hash != content_hash(script):
            report.sidecar.append("content_hash does not match the script (edited after it was added?)")
        for missing in entry.missing_files():
            report.sidecar.append(f"the provenance names {missing!r}, which is not in the entry folder "
                                  "(restore it, or re-add the entry with its files)")

        if entry.map not in list_maps() and not entry.map.endswith(".xodr"):
            report.sidecar.append(f"map {entry.map!r} is not a shipped map")
        if report.safety:
            report.error = "unsafe script"
            return report
        start = time.perf_counter()
        # the text read (and checked) once, never the path again: the file may be swapped in between
        ref = ScenarioRef(name=name, path=str(entry.script_path), source=script)
        env = DV2SEnv(scenario=[ref], config={"duration": seconds})  # compiles (in the jail when untrusted)
        report.compile_seconds = round(time.perf_counter() - start, 3)
        for seed in range(samples):
            obs, info = env.reset(seed=seed)
            report.samples += 1
            report.sampling_iterations += int(info.get("sample_iterations") or 0)
            terminated = truncated = False
            steps = 0
            while not (terminated or truncated):
                obs, reward, terminated, truncated, info = env.step(1)
                steps += 1
            report.episodes.append({"seed": seed, "steps": steps, "outcome": _outcome(info, terminated, truncated)})
        env.close()
        report.ok = not report.sidecar
        if report.sidecar:
            report.error = "; ".join(report.sidecar)
    except Exception as error:  # every failure becomes a line of the report
        report.error = f"{type(error).__name__}: {error}"
    return report


def validate_bank(
    bank_root: Optional[str] = None,
    names: Optional[Sequence[str]] = None,
    samples: int = 3,
    seconds: float = 3.0,
    jobs: int = 1,
    progress: bool = True,
) -> List[EntryReport]:
    """Validate entries (all by default), in ``jobs`` processes; broken sidecars are reported too."""
    bank = Bank(bank_root)
    chosen = list(names) if names else bank.names()
    reports: List[EntryReport] = [EntryReport(n, error=msg) for n, msg in sorted(bank.problems.items())
                                  if not names or n in names]
    bar = tqdm(total=len(chosen), desc="validating", unit="scenario", disable=not progress)
    if jobs <= 1:
        for n in chosen:
            reports.append(validate_entry(bank_root, n, samples, seconds))
            bar.update()
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(validate_entry, bank_root, n, samples, seconds) for n in chosen]
            for future in futures:
                reports.append(future.result())
                bar.update()
    bar.close()
    return sorted(reports, key=lambda r: r.name)
