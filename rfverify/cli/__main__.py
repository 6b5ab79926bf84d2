"""``python -m rfverify.cli`` is the ``rfverify`` command."""

import sys

from .app import main

sys.exit(main())
