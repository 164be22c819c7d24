"""``python -m wbc.cli``: the ``wbc`` command without its console script, ended as that script's entry ends it."""

import sys

from wbc.command import main

if __name__ == "__main__":  # a spawned worker re-imports the main module: it must not run the command again
    sys.exit(main())
