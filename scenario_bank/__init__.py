"""The scenario bank: randomized Scenic scenarios with metadata sidecars, their maps, and the jail
that runs untrusted Scenic.

This is the bottom layer of dv2s-gym: it imports nothing else of the project, so it also holds what every layer
above it shares. Each shipped scenario is a folder ``scenarios/<name>/`` holding ``scenario.scenic`` and its
sidecar ``meta.json`` (description, elements, story, tags, map, source, content hash); a user's bank has the same
layout.

The bank itself:

- :mod:`scenario_bank.bank`: :class:`~scenario_bank.bank.Bank`, the one interface that reads and writes
  a bank folder (atomically, under a writers' lock; its index cached in :mod:`scenario_bank.cache`), built of
  :mod:`scenario_bank.entries` (an entry folder, its sidecar and provenance, listing a bank folder),
  :mod:`scenario_bank.dedup` (when two scenarios are the same or near-duplicates),
  :mod:`scenario_bank.admission` (the checks a script passes to enter a bank) and
  :mod:`scenario_bank.archives` (export and import of ``.tar.gz`` archives);
- :mod:`scenario_bank.catalog` finds scenarios by name, tag or path; :mod:`scenario_bank.families` groups a bank's
  scenarios into families by lineage and by content;
- :mod:`scenario_bank.elements` and :mod:`scenario_bank.story` are the vocabulary of a sidecar's elements and
  story;
- :mod:`scenario_bank.safety`, :mod:`scenario_bank.precheck`, :mod:`scenario_bank.scenic_parse` and
  :mod:`scenario_bank.sandbox` check an untrusted script, and :mod:`scenario_bank.jail` runs it in a child
  process under CPU, memory and time limits (:mod:`scenario_bank.simulator_worker` is the seam to the simulator
  it runs); :mod:`scenario_bank.shipped` pins the shipped scripts by hash;
- :mod:`scenario_bank.scenic2` (with its rules, :mod:`scenario_bank.scenic2_rules`) upgrades Scenic 2 scripts;
- :mod:`scenario_bank.map_cache` keeps Scenic's parsed maps (``maps/`` holds the OpenDRIVE maps).

Shared by every layer (they sit here because this is the layer all others may import):

- :mod:`scenario_bank.errors` holds the one base error every project error derives from, and the bank's errors;
- :mod:`scenario_bank.records` holds the typed records the subsystems hand each other (a sidecar and its
  provenance; the episode records of the miner, the regression runner and the held-out evaluation), each read
  from and written back to exactly its JSON;
- :mod:`scenario_bank.atomic` (atomic file writes) and :mod:`scenario_bank.safe_files` (capped reads of
  regular files, safe names, archive extraction) are what every write and read of a user's folder goes through;
- :mod:`scenario_bank.named_registry` is the one registry type (policies, samplers, task kinds, backends, failure
  types, detectors) and :mod:`scenario_bank.plugins` loads the user's plug-in modules, in every worker process too;
- :mod:`scenario_bank.failure_types` is the table of failure types and what each part of the project reads of them;
- :mod:`scenario_bank.run_identity` is the check that a resumed run (training, DAgger, mining, the loop,
  regression) is the run its folder records;
- :mod:`scenario_bank.field_checks` checks the fields of the settings dataclasses and :mod:`scenario_bank.extras`
  names the optional dependency a missing import needs.
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
