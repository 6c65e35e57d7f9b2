"""Shared fixtures and the documented test tolerances."""

from __future__ import annotations

import os

from hypothesis import settings

# Property tests: deterministic and bounded so that the suite fits 2 cores.
settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=60, deadline=None, derandomize=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
