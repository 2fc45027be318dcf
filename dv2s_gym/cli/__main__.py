"""``python -m dv2s_gym.cli``: the ``dv2s`` command."""

import sys

from dv2s_gym.cli import main

__all__ = []

sys.exit(main())
