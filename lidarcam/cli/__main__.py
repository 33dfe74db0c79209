"""``python -m lidarcam.cli``: the same as the ``lidarcam`` command."""

import sys

from . import main

sys.exit(main())
