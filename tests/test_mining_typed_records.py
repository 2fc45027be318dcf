"""The mining modules that read episode records pass typed records to each other, not string-keyed dicts.

The modules of :data:`TYPED_MODULES` read a run's episodes as :class:`scenario_bank.records.EpisodeRecord` (by
their fields) and hand each other frozen records (``Behaviour``, ``FailureEntry``, ``ClusterEntry``,
``RateEstimate``, ``FailureRate``, ``FamilyGroup``, ``FamilySplit``); their JSON form, the one the files hold, is
each record's ``to_dict``. No public function of theirs takes or returns a ``Dict[str, Any]`` or
``Mapping[str, Any]`` (or a bare ``dict``) unless :data:`JSON_BOUNDARIES` lists it with the reason: the ones that
read or write a file format, or take a structure another module owns that has no typed record yet. The modules are
parsed, not imported.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path
from typing import Dict, List

ROOT = Path(__file__).resolve().parents[1]
MINING = ROOT / "dv2s_gym" / "mining"

TYPED_MODULES = ("behaviour", "cluster", "family", "rate", "report", "split")
"""The mining modules whose functions pass typed records."""

JSON_BOUNDARIES: Dict[str, str] = {
    "report.read_jsonl": "reads the JSON objects of a run's .jsonl files: the file format",
    "report.read_run": "returns the run's conversion records as read; their format is owned by the conversion "
                       "(dv2s_gym.mining.convert), which has no typed record for them yet",
    "report.build_report": "returns the report's JSON object: the schema of report.json (module docstring)",
    "report.build_report_from_records": "takes the run's settings.json and conversion records as read and returns "
                                        "the report's JSON object",
    "report.headline": "renders the report's JSON object (report.json)",
    "report.format_summary": "renders the report's JSON object (report.json)",
    "report.markdown": "renders the report's JSON object (report.json)",
    "report.write_reports": "writes the report's JSON object (report.json) and its renderings",
    "rate.rate_estimates": "takes the run's settings.json (a RunSettings is a read-only mapping over it)",
    "split.family_of": "takes one of the loop's mined entries (dv2s_gym.mining.loop.mined_entries), which the loop owns",
    "split.family_groups": "takes the loop's mined entries (dv2s_gym.mining.loop.mined_entries), which the loop owns",
    "split.split_by_family": "takes the loop's mined entries (dv2s_gym.mining.loop.mined_entries), which the loop owns",
}
"""``"module.function"`` of the typed modules that take or return a JSON object, each with the reason. A record's
``to_dict`` (its JSON form) needs no entry."""

EPISODE_READERS = {
    "behaviour.behaviour_of": "record", "family.record_family": "record", "cluster.cluster_id": "record",
    "cluster.cell_id": "record", "cluster.pair_of": "record", "cluster.cluster_failures": "records",
    "cluster.group": "records", "rate.failure_rate": "records", "rate.rate_estimates": "records",
    "report.build_report_from_records": "episodes",
}
"""``"module.function": parameter`` of the functions that read episode records: each is annotated with
:class:`~scenario_bank.records.EpisodeRecord`."""

_JSON_TYPES = ("Dict[str, Any]", "Mapping[str, Any]", "dict[str, Any]")


def _is_json_object(annotation: ast.expr | None) -> bool:
    """Whether an annotation names a string-keyed JSON object (anywhere in it: ``List[Dict[str, Any]]`` too)."""
    if annotation is None:
        return False
    text = ast.unparse(annotation).replace("typing.", "").strip("'\"")
    return any(name in text for name in _JSON_TYPES) or text in ("dict", "Dict", "Mapping")


def _public_functions(tree: ast.Module) -> Dict[str, ast.FunctionDef]:
    """``{"function" | "Class.method": node}`` of a module's public functions and its public classes' public
    methods."""
    found: Dict[str, ast.FunctionDef] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            found[node.name] = node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and not item.name.startswith("_"):
                    found[f"{node.name}.{item.name}"] = item
    return found


def json_object_functions(source: str) -> List[str]:
    """The public functions of a module's ``source`` that take or return a JSON object (but a ``to_dict``)."""
    found = []
    for name, node in _public_functions(ast.parse(source)).items():
        if name.endswith(".to_dict"):
            continue
        arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
        arguments += [a for a in (node.args.vararg, node.args.kwarg) if a is not None]
        if _is_json_object(node.returns) or any(_is_json_object(a.annotation) for a in arguments):
            found.append(name)
    return found


def _source(module: str) -> str:
    return (MINING / f"{module}.py").read_text(encoding="utf-8")


def test_the_check_sees_a_json_object_taken_or_returned():
    planted = textwrap.dedent("""
        from typing import Any, Dict, List, Mapping, Optional

        def takes(record: Dict[str, Any]) -> int: ...
        def returns(n: int) -> Optional[Mapping[str, Any]]: ...
        def in_a_list(*rows: List[Dict[str, Any]]) -> None: ...
        def bare(row: dict) -> None: ...
        def typed(row: "EpisodeRecord") -> Dict[str, int]: ...
        def _private(row: Dict[str, Any]) -> None: ...

        class Record:
            def to_dict(self) -> Dict[str, Any]: ...
            def named(self, *, extra: Mapping[str, Any] = None) -> str: ...
    """)
    assert json_object_functions(planted) == ["takes", "returns", "in_a_list", "bare", "Record.named"]


def test_the_typed_modules_pass_typed_records():
    found = [f"{module}.{name}" for module in TYPED_MODULES for name in json_object_functions(_source(module))]
    unlisted = [name for name in found if name not in JSON_BOUNDARIES]
    assert not unlisted, (f"{unlisted} take or return a string-keyed dict; pass a typed record (EpisodeRecord or a "
                          "frozen record of the module that owns it, with to_dict for its JSON form), or list it in "
                          "JSON_BOUNDARIES with the reason")
    stale = sorted(set(JSON_BOUNDARIES) - set(found))
    assert not stale, f"{stale} no longer take or return a JSON object: remove them from JSON_BOUNDARIES"


def test_the_functions_that_read_episodes_take_episode_records():
    untyped = []
    for qualified, parameter in EPISODE_READERS.items():
        module, name = qualified.split(".")
        node = _public_functions(ast.parse(_source(module)))[name]
        annotation = next(a.annotation for a in node.args.args + node.args.kwonlyargs if a.arg == parameter)
        if "EpisodeRecord" not in ast.unparse(annotation):
            untyped.append(f"{qualified}({parameter}: {ast.unparse(annotation)})")
    assert not untyped, f"{untyped} read episode records: annotate them EpisodeRecord and read their fields"
