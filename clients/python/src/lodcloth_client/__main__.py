"""``python -m lodcloth_client`` is ``lodcloth-py``."""

import sys

from .cli import main

sys.exit(main())
