"""``python -m pytest_hevval`` is the ``hevval`` command."""

from .cli import main

raise SystemExit(main())
