"""``python -m terrainvis.cli``: the command line, as the ``terrainvis`` script runs it."""

from . import console

console()
