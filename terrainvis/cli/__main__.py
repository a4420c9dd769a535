"""``python -m terrainvis.cli``: the command line, as the ``terrainvis`` script runs it."""

import sys

from . import main

sys.exit(main())
