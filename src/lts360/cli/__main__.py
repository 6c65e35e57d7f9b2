"""``python -m lts360.cli``."""

import sys

from lts360.cli import main

sys.exit(main())
