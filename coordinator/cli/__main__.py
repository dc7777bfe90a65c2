"""``python -m coordinator.cli``: the ``surge`` command."""

import sys

from coordinator.cli import main

sys.exit(main())
