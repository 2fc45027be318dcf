"""Policies that break the worker running them, loaded by spec (``regress_misbehaving_policies:crash``)
in tests of the backends' crash and hang handling. The tests put this folder on the workers' path."""

import os
import time


def crash(*_args, **_options):
    """Kill the worker process at once (on the first action), as a segfault or the OOM killer would."""
    os._exit(3)


def hang(*_args, **_options):
    """Never return."""
    while True:
        time.sleep(60)
