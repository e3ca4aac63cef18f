"""``python -m liesuslov``: the command-line front door (see :mod:`liesuslov.cli`)."""

from .cli import main

raise SystemExit(main())
