"""``python -m benchmarks.cli`` is the ``piezotwin`` command."""

import sys

from benchmarks.cli.main import main

sys.exit(main())
