"""``python -m starnav.cli``: the ``starnav`` command."""

import sys

from starnav.cli import main

sys.exit(main())
