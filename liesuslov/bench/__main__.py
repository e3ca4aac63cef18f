"""``python -m liesuslov.bench``: the benchmark's command line (see :mod:`liesuslov.bench.cli`)."""

import sys

from .cli import main

sys.exit(main())
