"""One way to add entries to a bank: an archive import stages its entries through the bank's public batch add, the
on_duplicate values are one set, and a sidecar's format is checked in one place (the Sidecar record)."""

import ast
import json
from pathlib import Path

import pytest

import scenario_bank.archives as archives
from scenario_bank.admission import ON_DUPLICATE, ON_DUPLICATE_OF, check_on_duplicate
from scenario_bank.bank import Bank
from scenario_bank.entries import validate_sidecar
from scenario_bank.errors import BankOptionError
from scenario_bank.records import RecordError, Sidecar

SHIPPED = Path(__file__).resolve().parents[1] / "scenario_bank" / "scenarios"


def test_archives_use_no_private_member_of_the_bank():
    used = [f"{node.attr} (line {node.lineno})" for node in ast.walk(ast.parse(Path(archives.__file__).read_text()))
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")]
    assert used == []


def test_on_duplicate_values_are_one_set():
    assert set().union(*ON_DUPLICATE_OF.values()) == set(ON_DUPLICATE)
    assert check_on_duplicate("skip", "import") == "skip"
    with pytest.raises(BankOptionError, match=r"not 'merge' \('merge' applies to add\)"):
        check_on_duplicate("merge", "import")
    with pytest.raises(ValueError, match="on_duplicate must be one of 'skip', 'error', not 'merge'"):
        Bank(Path("/nonexistent-bank")).import_archive("/nonexistent.tar.gz", on_duplicate="merge")


def test_a_batch_add_into_a_read_only_bank_is_refused_before_anything_is_written():
    with pytest.raises(Exception, match="read-only"):
        with Bank().add_together("import scenarios"):
            pass


def test_the_sidecar_record_is_the_one_check_of_the_format(tmp_path):
    folder = tmp_path / "entry"
    folder.mkdir()
    (folder / "scenario.scenic").write_text("ego = new Car\n")
    meta = json.loads((SHIPPED / "highway_lead_vehicle_brakes" / "meta.json").read_text())
    assert validate_sidecar(dict(meta), folder).to_dict()["elements"] == meta["elements"]
    for bad, said in [({**meta, "source": {"kind": "mined", "seed": "x"}}, "sidecar field 'source.seed' must be an integer"),
                      ({**meta, "description": ""}, "'description' is missing or not a non-empty string"),
                      ({**meta, "source": {"kind": "mined", "files": ["../x"]}}, "not a file inside the entry folder"),
                      ({**meta, "elements": {"road": "moon"}}, "sidecar elements: unknown road")]:
        with pytest.raises(RecordError, match=said):
            Sidecar.from_dict(bad)
        with pytest.raises(RecordError, match=said):
            validate_sidecar(dict(bad), folder)
