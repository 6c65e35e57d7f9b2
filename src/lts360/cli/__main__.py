"""``python -m lts360.cli``."""

from lts360.cli import run

run()
