"""The scenario bank: randomized Scenic scenarios with metadata sidecars, their maps, and the jail
that runs untrusted Scenic.

This is the bottom layer of dv2s-gym: it imports nothing else of the project. Each shipped
scenario is a folder ``scenarios/<name>/`` holding ``scenario.scenic`` and its sidecar
``meta.json`` (description, elements, story, tags, map, source, content hash); a user's bank has
the same layout. :mod:`scenario_bank.bank` reads and writes banks (atomically),
:mod:`scenario_bank.catalog` finds scenarios by name, tag or path, :mod:`scenario_bank.jail`
runs scripts in a child process under CPU, memory and time limits.
"""

from scenario_bank.catalog import (
    BANK_DIR,
    UnknownScenarioError,
    list_scenarios,
    scenario_metadata,
    scenario_path,
    select_scenarios,
)

__all__ = [
    "BANK_DIR",
    "UnknownScenarioError",
    "list_scenarios",
    "scenario_metadata",
    "scenario_path",
    "select_scenarios",
]
