"""``python -m liesuslov``: the command-line front door (see :mod:`liesuslov.cli`)."""

from .cli import main

if __name__ == "__main__":
    raise SystemExit(main())
