"""The scenario bank: randomized Scenic scenarios with metadata sidecars, and their maps.

This is the bottom layer of dv2s-gym: it imports nothing else of the project.
Each scenario is ``scenarios/<name>.scenic`` beside ``scenarios/<name>.json``
(description, tags, map, use case, source).
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
