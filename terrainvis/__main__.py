"""``python -m terrainvis``: the command line, as the ``terrainvis`` script runs it."""

import sys

from .cli import main

sys.exit(main())
