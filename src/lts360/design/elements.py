"""One evaluation of the design model: the (case, θ) elements and what every stage reads.

The model (:mod:`lts360.design.model`) evaluates, for each design, each case (a section
radius and a placement of its centre) and each θ of a uniform grid, one *element*: the
section point ``X`` and its outward normal.  The stages (laser, camera, noise, coverage,
shares) are functions of an :class:`Elements` and of the dicts the earlier stages return.
"""

from __future__ import annotations

import dataclasses

__all__ = ["Elements"]


@dataclasses.dataclass
class Elements:
    """The Dr.Jit values of one evaluation that every stage reads.

    ``o`` the back end (:class:`lts360.design.backend.DrJitOps`); ``cond`` the
    :class:`~lts360.design.model.Conditions`; ``base`` the base rig; ``P`` the parameters
    (full-width arrays, by name); ``geo`` the camera, mirrors and laser
    (:func:`lts360.design.camera.rig_geometry`); ``dist`` the base camera's distortion;
    ``k`` the sharpness and ``w_mm``, ``w_px``, ``w_cos`` the smooth steps' widths;
    ``cos_max`` the incidence limit; the elements ``ci`` (case index), ``theta``, ``ct``,
    ``st``, ``r``, ``cxy`` (centre), ``normal``, ``X`` (mm); ``seqs`` the mirror sequences
    and ``names`` their views; ``n_th`` θ samples per case.
    """

    o: object
    cond: object
    base: object
    P: dict
    geo: dict
    dist: object
    k: float
    w_mm: float
    w_px: float
    w_cos: float
    cos_max: float
    n_th: int
    ci: object
    theta: object
    ct: object
    st: object
    r: object
    cxy: tuple
    normal: object
    X: object
    seqs: list
    names: list

    def case_sum(self, value):
        """Per case, the sum over its θ elements (the elements are case-major)."""
        return self.o.dr.block_sum(value + 0.0 * self.ct, self.n_th)
