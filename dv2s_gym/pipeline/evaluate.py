"""``dv2s eval dra|sg|e2e``: the paper's metrics over a labeled folder.

A labeled folder holds videos (``.mp4 .webm .avi .mkv .gif``) and/or description
files (``.txt``), each with ``<stem>.label.json``::

    {"use_case": "collision_risk_avoidance_highway",
     "description": "optional reference description (used by `eval sg` when no .txt)",
     "elements": {"road": "highway", "participants": [...], "actions": [...], "relations": [...]}}

or the flat form with the element fields at the top level (see :mod:`dv2s_gym.pipeline.labels`).

``eval sg`` scores SP = |S_de ∩ S_sc| / |S_de| with S_de the labelled elements
wherever a label exists; a description (``.txt``) without a label is scored against
the elements parsed from its text. The table and each item say which was used.
``eval dra`` and ``eval e2e`` need a label for every item.

Results are printed per use case and overall as mean ± sd, like the paper's tables.
"""

from __future__ import annotations

import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from tqdm import tqdm

from dv2s_gym.pipeline.labels import LABEL_SUFFIX, read_label
from dv2s_gym.pipeline.llm_config import LLMConfigLike
from dv2s_gym.pipeline.metrics import e2e_sc, hallucination_rate, mean_sd, scs, semantic_preservation
from dv2s_gym.pipeline.convert import check_scenario
from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.stages import describe, generate
from scenario_bank.elements import Elements
from scenario_bank.errors import MissingFileError, SettingError

__all__ = ["EvalItem", "EVALSET_DIR", "EVALSETS", "evalset_folder", "collect_items", "evaluate", "format_results", "VIDEO_SUFFIXES"]

VIDEO_SUFFIXES = (".mp4", ".webm", ".avi", ".mkv", ".gif")
EVALSET_DIR = Path(__file__).resolve().parents[1] / "evalset"
"""The labeled evaluation set shipped with dv2s-gym (bird's-eye clips of every bank use case)."""
EVALSETS = {"in-house": EVALSET_DIR, "in-house-descriptions": EVALSET_DIR / "descriptions"}
"""The evaluation sets shipped with dv2s-gym by name (``dv2s eval STAGE --set NAME``): the in-house clips and the
descriptions written by hand from public sources."""


def evalset_folder(name: str) -> Path:
    """The folder of the shipped evaluation set called ``name`` (one of :data:`EVALSETS`)."""
    if name not in EVALSETS:
        raise SettingError(f"unknown evaluation set {name!r}; the shipped sets are {', '.join(EVALSETS)} "
                           "(or pass a labeled folder)")
    return EVALSETS[name]


@dataclass
class EvalItem:
    """One input: a video or a description, with its ground truth (``elements`` is None without a label)."""

    stem: str
    use_case: str
    elements: Optional[Elements]
    video: Optional[str] = None
    description: Optional[str] = None


@dataclass
class ItemResult:
    stem: str
    use_case: str
    metrics: Dict[str, float] = field(default_factory=dict)
    ok: bool = True
    seconds: float = 0.0
    error: Optional[str] = None
    detail: Dict[str, Any] = field(default_factory=dict)
    reference: Optional[str] = None
    """``eval sg``: where S_de came from, ``label`` or ``text`` (the parsed description)."""


def collect_items(folder: str | Path, *, unlabeled_descriptions: bool = False) -> List[EvalItem]:
    """Every labeled video/description in ``folder`` (read in either label format, see
    :mod:`dv2s_gym.pipeline.labels`); with ``unlabeled_descriptions``, also every ``.txt``
    description that has no label (its ``elements`` is None).

    Raises :class:`~dv2s_gym.pipeline.labels.LabelError` for a malformed label file.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingFileError(f"evaluation folder {str(folder)!r} does not exist; pass a folder of videos or "
                               f"descriptions (.txt) each with its label file (<name>{LABEL_SUFFIX}), or name a "
                               f"shipped set with --set ({', '.join(EVALSETS)})")
    items = []
    for label_path in sorted(folder.glob(f"*{LABEL_SUFFIX}")):
        stem = label_path.name[: -len(LABEL_SUFFIX)]
        label = read_label(label_path)
        video = next((str(folder / f"{stem}{s}") for s in VIDEO_SUFFIXES if (folder / f"{stem}{s}").is_file()), None)
        text_file = folder / f"{stem}.txt"
        description = text_file.read_text(encoding="utf-8") if text_file.is_file() else label.description
        items.append(EvalItem(stem, label.use_case or "unlabeled", label.elements, video, description))
    if unlabeled_descriptions:
        labeled = {item.stem for item in items}
        for text_file in sorted(folder.glob("*.txt")):
            if text_file.stem not in labeled:
                items.append(EvalItem(text_file.stem, "unlabeled", None, None, text_file.read_text(encoding="utf-8")))
        items.sort(key=lambda item: item.stem)
    if not items:
        wanted = "<name>.label.json or <name>.txt" if unlabeled_descriptions else "<name>.label.json"
        raise MissingFileError(f"no {wanted} files in {folder}; see `dv2s eval --help` for the format")
    return items


def _evaluate_item(stage: str, item: EvalItem, dra: str, sg: str, llm_config: LLMConfigLike,
                   seconds: float) -> ItemResult:
    result = ItemResult(item.stem, item.use_case)
    start = time.perf_counter()
    try:
        if stage in ("dra", "e2e"):
            if item.video is None:
                raise MissingFileError(f"{item.stem}: no video beside its label")
            description = describe(item.video, backend=dra, llm_config=llm_config)
            text, described = description.text, description.elements
            result.detail["description"] = text
            if stage == "dra":
                result.metrics = {"SCS": scs(item.elements, described), "HR": hallucination_rate(item.elements, described)}
        else:
            if not item.description:
                raise MissingFileError(f"{item.stem}: no description (.txt or label 'description')")
            text = item.description
            # S_de: the labelled elements; the description's parse only where there is no label
            if item.elements is not None:
                described, result.reference = item.elements, "label"
            else:
                described, result.reference = elements_from_text(text), "text"
        if stage in ("sg", "e2e"):
            generation = generate(text, backend=sg, llm_config=llm_config)
            check = check_scenario(generation.script, seconds=seconds, name=item.stem)
            if check.ran:
                generation.note_simulated(check.simulated_elements)
            result.ok = check.ok
            result.detail.update({"warnings": generation.warnings, "failures": generation.failure_counts(),
                                  "check_error": check.error,
                                  "simulated": {} if check.simulated_elements is None
                                  else check.simulated_elements.to_dict()})
            simulated = (check.simulated_elements if check.ran else None) or Elements()
            if stage == "sg":
                result.metrics = {"SP": semantic_preservation(described, simulated)}
            else:
                result.metrics = {"E2E-SC": e2e_sc(item.elements, simulated)}
    except Exception as error:  # a failed item scores what it scored and is reported
        result.ok = False
        result.error = f"{type(error).__name__}: {error}"
        result.metrics = {"dra": {"SCS": 0.0, "HR": 1.0}, "sg": {"SP": 0.0}, "e2e": {"E2E-SC": 0.0}}[stage]
    result.seconds = round(time.perf_counter() - start, 3)
    return result


def evaluate(stage: str, folder: str | Path, *, dra: str = "bev", sg: str = "rules",
             llm_config: LLMConfigLike = None, jobs: int = 1, seconds: float = 10.0,
             progress: bool = True) -> Dict[str, Any]:
    """Run one evaluation; returns per-item results and the per-use-case / overall summary."""
    if stage not in ("dra", "sg", "e2e"):
        raise SettingError(f"unknown evaluation {stage!r}; use dra, sg or e2e")
    items = collect_items(folder, unlabeled_descriptions=stage == "sg")
    bar = tqdm(total=len(items), desc=f"eval {stage}", unit="item", disable=not progress)
    results: List[ItemResult] = []
    if jobs <= 1:
        for item in items:
            results.append(_evaluate_item(stage, item, dra, sg, llm_config, seconds))
            bar.update()
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_evaluate_item, stage, item, dra, sg, llm_config, seconds) for item in items]
            for future in futures:
                results.append(future.result())
                bar.update()
    bar.close()
    return {"stage": stage, "backends": {"dra": dra, "sg": sg}, "items": [r.__dict__ for r in results],
            "summary": summarize(results)}


def summarize(results: Sequence[ItemResult]) -> Dict[str, Any]:
    groups: Dict[str, List[ItemResult]] = defaultdict(list)
    for r in results:
        groups[r.use_case].append(r)
    names = sorted({m for r in results for m in r.metrics})

    def block(rs: Sequence[ItemResult]) -> Dict[str, Any]:
        out = {m: mean_sd(r.metrics[m] for r in rs if m in r.metrics) for m in names}
        out["ok_rate"] = sum(r.ok for r in rs) / len(rs)
        out["seconds_mean"] = sum(r.seconds for r in rs) / len(rs)
        if any(r.reference for r in rs):
            out["reference"] = {source: sum(r.reference == source for r in rs) for source in ("label", "text")}
        return out

    return {"per_use_case": {u: block(rs) for u, rs in sorted(groups.items())}, "overall": block(results)}


def _reference_cell(block: Dict[str, Any]) -> str:
    counts = block.get("reference") or {}
    return ", ".join(f"{source} {n}" for source, n in counts.items() if n) or "-"


def format_results(report: Dict[str, Any]) -> str:
    """A table like the paper's: rows per use case and overall, columns mean ± sd per metric.

    For ``eval sg`` a column ``S_de from`` counts the items scored against their label file
    (``label``) and against the parse of their description (``text``), and a closing line says it.
    """
    summary = report["summary"]
    skip = ("ok_rate", "seconds_mean", "reference")
    metrics = [m for m in summary["overall"] if m not in skip]
    with_reference = "reference" in summary["overall"]
    header = ["use case", *metrics, *(["S_de from"] if with_reference else []), "n", "ran ok", "s/item"]
    rows = []
    for name, block in [*summary["per_use_case"].items(), ("overall", summary["overall"])]:
        n = next((block[m]["n"] for m in metrics), 0)
        rows.append([name, *(f"{block[m]['mean']:.2f} ± {block[m]['sd']:.2f}" for m in metrics),
                     *([_reference_cell(block)] if with_reference else []), str(n),
                     f"{100 * block['ok_rate']:.0f}%", f"{block['seconds_mean']:.2f}"])
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    line = lambda cells: "  ".join(c.ljust(w) for c, w in zip(cells, widths))  # noqa: E731
    failed = [f"  {i['stem']}: {i['error']}" for i in report["items"] if i.get("error")]
    notes = []
    if with_reference:
        counts = summary["overall"]["reference"]
        notes.append(f"SP reference S_de: {counts['label']} item(s) scored against their label file, "
                     f"{counts['text']} against the parse of their description (no label).")
        unlabeled = [i["stem"] for i in report["items"] if i.get("reference") == "text"]
        if unlabeled:
            notes.append(f"  scored against the parsed description: {', '.join(unlabeled)}")
    return "\n".join([line(header), line(["-" * w for w in widths]), *map(line, rows), *notes,
                      *(["failed items:"] + failed if failed else [])])
