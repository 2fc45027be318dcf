"""Label files (``<stem>.label.json``): the ground-truth semantic elements of a video or description.

Two formats are read, both JSON objects:

* nested: the elements under ``"elements"``, beside optional metadata::

    {"use_case": "highway_lead_vehicle_brakes", "description": "...",
     "elements": {"road": "highway", "participants": ["ego", "car"], ...}}

* flat: the element fields at the top level (the vocabulary's own format), with the
  same optional metadata beside them::

    {"road": "highway", "participants": ["ego", "car"], "actions": [["car", "brake"]],
     "relations": [["car", "ahead_of", "ego"]]}

Elements are checked against the vocabulary (:mod:`scenario_bank.elements`); anything
else is a :class:`LabelError` naming the file and what is wrong with it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Optional

from dv2s_gym.pipeline.errors import PipelineError
from scenario_bank.elements import ElementError, Elements

__all__ = ["Label", "LabelError", "LABEL_SUFFIX", "read_label", "label_path_for"]

LABEL_SUFFIX = ".label.json"
ELEMENT_FIELDS = ("road", "participants", "actions", "relations")
_FORMATS = ('nested {"elements": {"road": ..., "participants": [...], "actions": [...], "relations": [...]}} '
            'or flat {"road": ..., "participants": [...], "actions": [...], "relations": [...]}')


class LabelError(PipelineError, ValueError):
    """A label file that cannot be read as ground-truth elements."""


@dataclass
class Label:
    """A read label: its elements and optional metadata."""

    path: Path
    elements: Elements
    use_case: Optional[str] = None
    description: Optional[str] = None
    format: str = "nested"


def label_path_for(path: Path) -> Path:
    """The label file beside a video or description file (``clip.webm`` -> ``clip.label.json``)."""
    return path.with_name(path.stem + LABEL_SUFFIX)


def read_label(path: str | Path) -> Label:
    """Read and validate a label file in either format; raises :class:`LabelError`."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LabelError(f"label file {path} does not exist") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise LabelError(f"label file {path} is not valid JSON ({error}); a label is {_FORMATS}") from None
    if not isinstance(data, dict):
        raise LabelError(f"label file {path} holds a JSON {type(data).__name__}, not an object; a label is {_FORMATS}")
    flat = [k for k in ELEMENT_FIELDS if k in data]
    if "elements" in data and flat:
        raise LabelError(f"label file {path} has both 'elements' and top-level element fields {flat}; "
                         "use one format: " + _FORMATS)
    if "elements" in data:
        elements, form = data["elements"], "nested"
    elif flat:
        elements, form = {k: data[k] for k in flat}, "flat"
    else:
        raise LabelError(f"label file {path} has no elements (no 'elements' and none of {list(ELEMENT_FIELDS)}); "
                         f"a label is {_FORMATS}")
    try:
        elements = Elements.from_dict(elements)
    except (ElementError, TypeError) as error:
        raise LabelError(f"label file {path}: {error}; a label is {_FORMATS}") from None
    for key in ("use_case", "description"):
        if data.get(key) is not None and not isinstance(data[key], str):
            raise LabelError(f"label file {path}: '{key}' must be a string, got {type(data[key]).__name__}")
    return Label(path, elements, data.get("use_case"), data.get("description"), form)
