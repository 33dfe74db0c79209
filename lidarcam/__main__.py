"""``python -m lidarcam``: the same as the ``lidarcam`` command."""

import sys

from .cli import main

sys.exit(main())
