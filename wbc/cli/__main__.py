"""``python -m wbc.cli``: the ``wbc`` command without its console script."""

import sys

from wbc.cli import main

if __name__ == "__main__":  # a spawned worker re-imports the main module: it must not run the command again
    sys.exit(main())
