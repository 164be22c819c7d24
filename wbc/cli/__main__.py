"""``python -m wbc.cli``: the ``wbc`` command without its console script."""

import sys

from wbc.cli.main import main

sys.exit(main())
