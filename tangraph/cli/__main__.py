"""``python -m tangraph.cli``: the ``tangraph`` command."""

import sys

from tangraph.cli import main

sys.exit(main())
