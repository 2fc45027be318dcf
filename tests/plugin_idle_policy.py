"""A plug-in policy, as a user writes one (docs/mining.md, "A plug-in policy"): ``plugin_idle`` keeps its lane and
speed. It registers when it is imported, so the worker processes (which import the plug-in modules of the process
that started them) know it too."""

from __future__ import annotations

from policies.registry import register_policy
from policies.state_driver import IDLE

NAME = "plugin_idle"

register_policy(NAME, lambda **options: (lambda obs: IDLE))
