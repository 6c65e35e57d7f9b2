"""lts360: a physically based simulation and synthetic-data testbed for 360° laser
triangulation with mirrors (one camera, one laser line, two mirrors at 90°)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("lts360")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"
