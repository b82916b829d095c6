"""``python -m starnav``: the ``starnav`` command."""

from starnav.cli import main

raise SystemExit(main())
