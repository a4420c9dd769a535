"""``python -m terrainvis``: the command line, as the ``terrainvis`` script runs it."""

from .cli import console

if __name__ == "__main__":  # a spawned process imports this module again (as __mp_main__): it must not run a command
    console()
