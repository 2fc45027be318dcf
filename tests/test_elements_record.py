"""The semantic elements are one typed record, :class:`scenario_bank.elements.Elements`, everywhere in the product.

The record checks its content against the vocabulary (the errors name the entry), holds it in canonical form (so
two records of the same content compare and hash equal) and writes back the JSON object the files hold. The
product's public functions take and return it (:func:`element_annotations`), and no product module reads one by
string key (:func:`keyed_element_reads`). The modules are parsed, not imported.
"""

from __future__ import annotations

import ast
import json
import re
import textwrap
from pathlib import Path
from typing import List

import pytest

from scenario_bank.elements import (ACTIONS, PARTICIPANTS, RELATIONS, ROADS, Action, ActorKind, ElementError, Elements,
                                    Relation, Road, element_set, empty_elements)
from scenario_bank.records import Sidecar
from tests.test_mining_typed_records import _key_reads

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenario_bank", "envs", "policies", "dv2s_gym")
FIELDS = ("road", "participants", "actions", "relations")

LABEL = {"road": "highway", "participants": ["ego", "car", "car"],
         "actions": [["car", "brake"], ["car", "brake"], ["car", "accelerate"]],
         "relations": [["car", "same_lane", "ego"], ["car", "ahead_of", "ego"]]}


def test_a_record_holds_its_content_in_canonical_form_and_writes_the_json_object():
    record = Elements.from_dict(LABEL)
    assert record.participants == ("car", "car", "ego")
    assert record.actions == (("car", "accelerate"), ("car", "brake"))
    assert record.to_dict() == {"road": "highway", "participants": ["car", "car", "ego"],
                                "actions": [["car", "accelerate"], ["car", "brake"]],
                                "relations": [["car", "ahead_of", "ego"], ["car", "same_lane", "ego"]]}
    assert list(record.to_dict()) == list(FIELDS)
    assert json.dumps(empty_elements().to_dict()) == '{"road": null, "participants": [], "actions": [], "relations": []}'
    assert Elements.from_dict(record.to_dict()) == record and Elements.from_dict(record) is record
    built = Elements("highway", ("ego", "car", "car"), (("car", "brake"), ("car", "accelerate")),
                     (("car", "ahead_of", "ego"), ("car", "same_lane", "ego")))
    assert built == record and hash(built) == hash(record) and len({built, record}) == 1
    assert record != Elements.from_dict({**LABEL, "road": "merge"}) and record != record.to_dict()


@pytest.mark.parametrize("data, message", [
    ([], "elements must be a JSON object, got list"),
    ({"road": "highway", "speed": 3}, "unknown element fields ['speed']; allowed: road, participants, actions, "
                                      "relations"),
    ({"road": "moon"}, "unknown road type 'moon'; use one of: highway,"),
    ({"participants": ["dog"]}, "unknown participant 'dog'; use one of: ego,"),
    ({"actions": [["car"]]}, "each action must be a list of 2 strings, got ['car']"),
    ({"actions": [["car", "fly"]]}, "unknown action 'fly'; use one of: brake,"),
    ({"relations": [["car", "under", "ego"]]}, "unknown relation 'under'; use one of: ahead_of,"),
])
def test_a_record_names_what_does_not_follow_the_vocabulary(data, message):
    with pytest.raises(ElementError) as error:
        Elements.from_dict(data)
    assert str(error.value).startswith(message)


def test_the_metrics_read_a_record_or_a_label_file_s_json_object_alike():
    assert element_set(Elements.from_dict(LABEL)) == element_set(LABEL)
    assert ("participant", "car", 2) in element_set(LABEL) and ("road", "highway") in element_set(LABEL)


def test_a_sidecar_holds_a_record_and_writes_its_elements_back_unchanged():
    meta = json.loads((ROOT / "scenario_bank/scenarios/highway_lead_vehicle_brakes/meta.json").read_text())
    sidecar = Sidecar.from_dict(meta)
    assert isinstance(sidecar.elements, Elements) and sidecar.elements.road == "highway"
    assert sidecar.to_dict()["elements"] == meta["elements"]
    assert isinstance(Sidecar.from_checked(sidecar.to_dict()).elements, Elements)
    no_road = {**meta, "elements": {**meta["elements"], "road": None}}
    assert json.dumps(Sidecar.from_dict(no_road).to_dict(), sort_keys=True) == json.dumps(no_road, sort_keys=True)
    unknown = {**meta, "elements": {**meta["elements"], "road": "moon"}}
    with pytest.raises(ValueError, match="sidecar elements: unknown road type 'moon'"):
        Sidecar.from_dict(unknown)


# ----------------------------------------------------------------------------------------------- the rules
_ELEMENT_PARAMETERS = ("elements", "known", "meant", "simulated")
"""Parameter names that hold an element record (and any name ending in ``_elements``)."""


def _holds_elements(name: str) -> bool:
    return name in _ELEMENT_PARAMETERS or name.endswith("_elements")


def _annotation(node) -> str:
    return "" if node is None else ast.unparse(node)


def _typed(annotation) -> bool:
    """Whether an annotation names an element record, what the metrics score (``ElementsLike``: a record, a label
    file's JSON object or a set) or a set of elements (``FrozenSet[Element]``)."""
    return re.search(r"\b(Elements|ElementsLike|Element)\b", _annotation(annotation)) is not None


def element_annotations(source: str) -> List[str]:
    """The public functions (and public classes' methods) of a module's ``source`` that take an element record
    (a parameter named as in :data:`_ELEMENT_PARAMETERS`) not annotated as an ``Elements``, the ``elements_from_*``
    functions that do not return one, and the dataclass fields named so that are not annotated as one."""
    found = []
    tree = ast.parse(source)
    functions = [(node.name, node) for node in tree.body if isinstance(node, ast.FunctionDef)]
    for cls in (node for node in tree.body if isinstance(node, ast.ClassDef) and not node.name.startswith("_")):
        functions += [(f"{cls.name}.{item.name}", item) for item in cls.body if isinstance(item, ast.FunctionDef)]
        for item in cls.body:
            if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name) \
                    and _holds_elements(item.target.id) and not _typed(item.annotation):
                found.append(f"{cls.name}.{item.target.id}: {_annotation(item.annotation)}")
    for name, node in functions:
        if name.split(".")[-1].startswith("_"):
            continue
        arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
        for argument in arguments:
            if _holds_elements(argument.arg) and not _typed(argument.annotation):
                found.append(f"{name}({argument.arg}: {_annotation(argument.annotation)})")
        if name.startswith("elements_from_") and not _typed(node.returns):
            found.append(f"{name} -> {_annotation(node.returns)}")
    return found


def keyed_element_reads(source: str) -> List[str]:
    """The string-key reads (``x["actions"]``, ``x.get("road")``) of an element field on a value whose name holds
    elements (``elements``, ``description.elements``, ``simulated_elements``...)."""
    found = []
    for node, target, key in _key_reads(ast.parse(source)):
        if "elements" in ast.unparse(target).split(".")[-1].rstrip("()") and key in FIELDS:
            found.append(ast.unparse(node))
    return found


def _product_sources():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


def test_the_rules_see_an_untyped_element_record_and_a_keyed_read():
    planted = textwrap.dedent("""
        from dataclasses import dataclass
        from typing import Any, Dict, Mapping, Optional

        def takes(elements: Dict[str, Any], known: Optional[Mapping[str, Any]] = None) -> int: ...
        def typed(elements: Elements, simulated: Optional[Elements], shown: Dict[str, Any]) -> bool: ...
        def widen(elements: FrozenSet[Element]) -> FrozenSet[Element]: ...
        def elements_from_video(video) -> Dict[str, Any]: ...
        def _private(elements: dict) -> None: ...

        @dataclass
        class Report:
            elements: Dict[str, Any]
            intended_elements: Optional[Elements] = None

            def score(self, meant) -> float:
                return self.elements["actions"], meant.get("road"), entry.elements.get("participants"), a["actions"]
    """)
    assert element_annotations(planted) == ["Report.elements: Dict[str, Any]", "takes(elements: Dict[str, Any])",
                                            "takes(known: Optional[Mapping[str, Any]])",
                                            "elements_from_video -> Dict[str, Any]", "Report.score(meant: )"]
    assert keyed_element_reads(planted) == ["self.elements['actions']", "entry.elements.get('participants')"]


def test_the_product_passes_element_records_typed_and_reads_their_fields():
    untyped = [f"{path}: {found}" for path, source in _product_sources() for found in element_annotations(source)]
    assert not untyped, (f"{untyped} take, return or hold semantic elements without the Elements annotation; "
                         "pass scenario_bank.elements.Elements (its to_dict() is the JSON object)")
    keyed = [f"{path}: {found}" for path, source in _product_sources() for found in keyed_element_reads(source)]
    assert not keyed, f"{keyed} read an element record by string key; read its fields (elements.actions)"


def test_the_vocabulary_tables_are_the_enums_values_as_plain_strings():
    """``ROADS``, ``PARTICIPANTS``, ``ACTIONS`` and ``RELATIONS`` hold the values of ``Road``, ``ActorKind``, ``Action``
    and ``Relation`` in their order, as plain strings (what the JSON and YAML files hold); a member compares and
    hashes as its string, so code compares with the members."""
    assert ROADS == ("highway", "straight_road", "intersection", "t_junction", "three_way", "roundabout", "merge")
    for table, enum in ((ROADS, Road), (PARTICIPANTS, ActorKind), (ACTIONS, Action), (RELATIONS, Relation)):
        assert table == tuple(enum) and all(type(word) is str for word in table)
        assert {member: 1 for member in enum} == {word: 1 for word in table}
    assert Road.MERGE == Action.MERGE == "merge" and Road.MERGE is not Action.MERGE
