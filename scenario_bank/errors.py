"""The one base class every dv2s-gym error derives from.

It lives in the bottom layer (``scenario_bank``) so that every package can derive
from it; ``envs.errors`` re-exports it. The ``dv2s`` command catches it once and
prints its message as one line: a project error names the problem and the fix.
"""

from __future__ import annotations

__all__ = ["DV2SError"]


class DV2SError(Exception):
    """Base class of dv2s-gym errors.

    ``expected`` is False for errors that signal a fault rather than bad input (a
    jailed worker that crashed); the command line then adds the ``--debug`` hint.
    """

    expected: bool = True
