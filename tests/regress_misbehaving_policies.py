"""Policies that break the worker running them, loaded by spec (``regress_misbehaving_policies:crash``)
in tests of the backends' crash and hang handling. The tests put this folder on the workers' path.

Each is a factory (callable without arguments, so loading the spec calls it) that returns itself as
the policy function ``obs -> action``; the misbehaviour happens on the first action, or at load with
``?at=load``."""

import os
import time


def crash(*args, at="act", **_options):
    """Kill the worker process at once (on the first action), as a segfault or the OOM killer would."""
    if args or at == "load":
        os._exit(3)
    return crash


def hang(*args, at="act", **_options):
    """Never return (on the first action, or at load with ``at=load``)."""
    if args or at == "load":
        while True:
            time.sleep(60)
    return hang
