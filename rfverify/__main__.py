"""``python -m rfverify`` is the ``rfverify`` command."""

import sys

from .cli import main

sys.exit(main())
