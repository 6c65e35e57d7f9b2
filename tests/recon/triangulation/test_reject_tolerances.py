"""The rejection's thresholds are one frozen, validated object, and the functions read it."""

import dataclasses
import inspect

import pytest

from lts360.recon.triangulation import reject
from lts360.recon.triangulation.reject_tolerances import TOLERANCES, RejectionTolerances


def test_frozen_and_validated():
    with pytest.raises(dataclasses.FrozenInstanceError):
        TOLERANCES.notch_depth_mm = 0.2
    with pytest.raises(ValueError, match="notch_depth_mm"):
        RejectionTolerances(notch_depth_mm=-0.01)
    with pytest.raises(ValueError, match="notch_scales_mm"):
        RejectionTolerances(notch_scales_mm=())
    assert dataclasses.replace(TOLERANCES, notch_depth_mm=0.1).notch_depth_mm == 0.1


@pytest.mark.parametrize("func, param, field", [
    (reject.reject_spurious, "notch_depth_mm", "notch_depth_mm"),
    (reject.reject_spurious, "fade_margin_mm", "fade_margin_mm"),
    (reject.reject_spurious, "max_flank_slope", "max_flank_slope"),
    (reject.reject_discontinuous, "k", "continuity_k"),
    (reject.fading_points, "short_margin_mm", "short_margin_mm"),
    (reject.notch_depth, "scales_mm", "notch_scales_mm"),
])
def test_function_defaults_are_the_tolerances(func, param, field):
    assert inspect.signature(func).parameters[param].default == getattr(TOLERANCES, field)


def test_every_threshold_has_its_reason():
    """Each field is documented by a ``#:`` comment in the module (its reason and measurement)."""
    import lts360.recon.triangulation.reject_tolerances as mod

    src = inspect.getsource(mod)
    for f in dataclasses.fields(RejectionTolerances):
        line = next(i for i, text in enumerate(src.splitlines())
                    if text.strip().startswith(f"{f.name}:"))
        assert src.splitlines()[line - 1].strip().startswith("#:"), f.name
