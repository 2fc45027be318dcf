"""``python -m dv2s_gym.cli``: the ``dv2s`` command."""

import sys

from dv2s_gym.cli import main

sys.exit(main())
