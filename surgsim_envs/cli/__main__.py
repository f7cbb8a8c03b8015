"""``python -m surgsim_envs.cli ...``: the ``surgsim`` command."""

import sys

from surgsim_envs.cli import main

sys.exit(main())
