"""Views of the section in one image (direct, through one or two mirrors) and their θ windows.

A *view* is the camera seen through an ordered sequence of mirrors (paper §3.2, Eq. 4).  A
point ``X_cam`` (camera frame) reaches the image of view ``a-b`` (light path object →
mirror ``a`` → mirror ``b`` → camera) at ``P · T_b · T_a · X_cam``: the camera sees the
mirror image of the mirror image.  With ``X_cam = T_cam_meas X_meas`` the grid of the
measurement frame maps to pixels by ``P · T_view · T_cam_meas``; the direct view has
``T_view = I``.  (At β = 90° the
two double reflections have equal ``T_view`` — the corner shows them side by side.)

The θ window of a view (:func:`view_windows`) is derived from the calibration, never typed in:
a grid point ``r (cos θ, sin θ, 0)`` of the measurement frame is in the window when, for
every tested radius of the grid's range,

1. the surface of a section centred on the axis faces the view's (virtual) camera: the angle
   between the radial normal and the direction to the virtual camera is below
   ``max_incidence_deg``;
2. the straight path to the virtual camera, folded at each mirror, meets every mirror on its
   reflecting side and — where the calibration knows the mirror's corners — inside its
   rectangle, and no segment is blocked by the object (an infinite cylinder of that radius
   about the axis, the conservative model of a long part) or by another mirror of known extent;
3. the point projects inside the image (``margin_px`` from the border of the pixel-centre hull).

The laser's reach is not tested: the calibration knows the laser plane but not the fan's apex
or extent.  A θ inside the window that no laser light reaches just gives ``NO_PEAK``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from lts360.geometry.camera import project_camera_points
from lts360.geometry.mirror import mirror_matrix, transform_plane
from lts360.geometry.mirror_path import PathMirror, path_valid, quad_extent
from lts360.recon.model import Calibration
from lts360.recon.view_points import DIRECT

__all__ = ["View", "make_views", "get_views", "view_transform", "project_meas_points",
           "view_windows", "seen_through_mirrors", "DEFAULT_MAX_INCIDENCE_DEG", "DIRECT"]

DEFAULT_MAX_INCIDENCE_DEG = 80.0
#: Radii tested across the grid's range when deriving windows (both ends and the middle).
DEFAULT_WINDOW_RADII = 3


@dataclass(frozen=True, eq=False)
class View:
    """One view of the section.

    Attributes
    ----------
    name : str
        ``"direct"``, a mirror name, or mirror names joined by ``"-"`` in the order the light
        meets them leaving the object (``"left-right"``: object → left → right → camera).
    mirrors : tuple of str
        That order.
    T_cam : (4, 4) float
        ``T_{m_k} ⋯ T_{m_1}`` (paper Eq. 3, camera frame): a real point ``X_cam`` appears in
        this view where ``T_cam X_cam`` projects (Eq. 4).  Identity for the direct view.
    """

    name: str
    mirrors: tuple[str, ...]
    T_cam: np.ndarray

    @property
    def n_reflections(self) -> int:
        return len(self.mirrors)

    @property
    def virtual_camera_cam_mm(self) -> np.ndarray:
        """Centre of the virtual camera in the camera frame, ``T_cam⁻¹ · 0``."""
        return np.linalg.solve(self.T_cam, np.array([0.0, 0.0, 0.0, 1.0]))[:3]


def _view(cal: Calibration, seq: tuple[str, ...]) -> View:
    T = np.eye(4)
    for name in seq:  # T = T_{m_k} ⋯ T_{m_1}
        m = cal.mirror(name)
        T = mirror_matrix(m.n, m.d_mm) @ T
    T.setflags(write=False)
    return View(name=DIRECT if not seq else "-".join(seq), mirrors=tuple(seq), T_cam=T)


def make_views(cal: Calibration, *, double_reflections: bool = False) -> dict[str, View]:
    """The direct view, one view per mirror and, optionally, every double reflection.

    Returns
    -------
    dict str → View
        In the order direct, single mirrors (calibration order), double reflections.
    """
    names = cal.mirror_names
    seqs: list[tuple[str, ...]] = [()] + [(n,) for n in names]
    if double_reflections:
        seqs += [s for s in itertools.product(names, repeat=2) if s[0] != s[1]]
    return {v.name: v for v in (_view(cal, s) for s in seqs)}


def get_views(cal: Calibration, names) -> tuple[View, ...]:
    """Views by name (``"direct"``, ``"left"``, ``"left-right"``, ...), validated."""
    if isinstance(names, str):
        names = (names,)
    out = []
    for name in names:
        seq = () if name == DIRECT else tuple(str(name).split("-"))
        unknown = [s for s in seq if s not in cal.mirror_names]
        if unknown or any(a == b for a, b in zip(seq[:-1], seq[1:])) or not name:
            raise ValueError(f"views: {name!r} is not a view of this calibration (direct, mirrors "
                             f"{list(cal.mirror_names)} or 'a-b' with a != b)")
        out.append(_view(cal, seq))
    if len({v.name for v in out}) != len(out):
        raise ValueError(f"views: names must be unique, got {list(names)}")
    return tuple(out)


def view_transform(cal: Calibration, view: View) -> np.ndarray:
    """(4, 4) map ``T_view · T_cam_meas``: measurement frame → the frame that ``K`` projects."""
    return view.T_cam @ cal.T_cam_meas


def project_meas_points(points_meas_mm, cal: Calibration, view: View) -> np.ndarray:
    """Pixels of measurement-frame points in a view (paper Eq. 4, with distortion).

    Parameters
    ----------
    points_meas_mm : (..., 3) float
    cal : Calibration
    view : View

    Returns
    -------
    (..., 2) float
        ``(u, v)``; NaN for points behind the (virtual) camera.
    """
    pts = np.asarray(points_meas_mm, dtype=float)
    if pts.shape[-1] != 3:
        raise ValueError(f"points_meas_mm must have shape (..., 3), got {pts.shape}")
    T = view_transform(cal, view)
    flat = pts.reshape(-1, 3)
    cam = flat @ T[:3, :3].T + T[:3, 3]
    return project_camera_points(cam, cal.K, cal.dist).reshape(pts.shape[:-1] + (2,))


# -- windows -----------------------------------------------------------------------------------

def _mirrors_in_meas(cal: Calibration) -> dict[str, PathMirror]:
    """The calibrated mirrors in the measurement frame, as the path test sees them (their
    corners where the calibration knows them, else an unknown extent)."""
    T_mc = cal.T_meas_cam
    out = {}
    for m in cal.mirrors:
        n, d = transform_plane(m.n, m.d_mm, T_mc[:3, :3], T_mc[:3, 3])
        corners = None if m.corners_mm is None else m.corners_mm @ T_mc[:3, :3].T + T_mc[:3, 3]
        out[m.name] = PathMirror(n=n, d=d, T=mirror_matrix(n, d),
                                 contains=None if corners is None else quad_extent(corners, n))
    return out


def _path_ok(points: np.ndarray, camera: np.ndarray, seq: tuple[str, ...],
             mirrors: dict[str, PathMirror], radius_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The path test (:func:`lts360.geometry.mirror_path.path_valid`) from points to the
    camera through the named mirrors; the segment that leaves the surface is left to the
    windows' facing test.  Returns the validity and the unit direction in which the path
    leaves the points."""
    names = list(mirrors)
    ok, leave, _ = path_valid(points, camera, [names.index(n) for n in seq],
                              [mirrors[n] for n in names], radius_mm,
                              occlude_first_segment=False)
    return ok, leave


def seen_through_mirrors(cal: Calibration, view: View, points_meas_mm) -> np.ndarray:
    """Whether each point's straight path to the view's virtual camera, folded at its mirrors,
    meets each mirror on its reflecting side and inside its known extent, and crosses no other
    mirror of known extent (the path test of the windows without the object: a grid point
    beyond a mirror's edge is not seen in this view, whatever the image shows there).

    Parameters
    ----------
    points_meas_mm : (..., 3) float

    Returns
    -------
    (...) bool
        All True for the direct view and for mirrors of unknown extent.
    """
    pts = np.asarray(points_meas_mm, dtype=float)
    flat = pts.reshape(-1, 3)
    if not view.mirrors:
        return np.ones(pts.shape[:-1], dtype=bool)
    mirrors = _mirrors_in_meas(cal)
    camera = cal.T_meas_cam[:3, 3].copy()
    ok, _ = _path_ok(flat, camera, view.mirrors, mirrors, 0.0)
    return ok.reshape(pts.shape[:-1])


def view_windows(cal: Calibration, radius_range_mm, theta_rad, max_incidence_deg: float =
                 DEFAULT_MAX_INCIDENCE_DEG, *, views=None, n_radii: int = DEFAULT_WINDOW_RADII,
                 margin_px: float = 0.0, normal_angle_rad=None) -> dict[str, np.ndarray]:
    """Per-view θ windows derived from the calibration (see the module docstring).

    Parameters
    ----------
    cal : Calibration
    radius_range_mm : (float, float), or two (nθ,) float
        ``(r_min, r_max)`` of the grid, the same at every θ or one per θ (a grid that follows
        a profile); the tests hold at ``n_radii`` radii spread over it.
    theta_rad : (nθ,) float
        Grid angles (measurement frame).
    max_incidence_deg : float, (0, 90]
        Largest angle between the radial surface normal and the direction to the virtual camera.
    views : sequence of str or View, optional
        Default: direct and every single-mirror view.
    n_radii : int, >= 1
    margin_px : float, >= 0
    normal_angle_rad : (nθ,) float, optional
        Direction of the surface's outward normal in the laser plane at each θ (default θ:
        a section centred on the axis); from a first-pass profile ``r(θ)`` it is
        ``θ − atan(r′/r)``, which keeps the facing test right for a part off the axis.

    Returns
    -------
    dict str → (nθ,) bool
    """
    theta = np.asarray(theta_rad, dtype=float).ravel()
    r0, r1 = (np.broadcast_to(np.asarray(v, dtype=float), theta.shape) for v in radius_range_mm)
    if not (np.all(0 < r0) and np.all(r0 <= r1)):
        raise ValueError(f"radius_range_mm must satisfy 0 < r_min <= r_max, got "
                         f"{np.min(r0)}..{np.max(r1)}")
    if not 0 < max_incidence_deg <= 90:
        raise ValueError(f"max_incidence_deg must be in (0, 90], got {max_incidence_deg}")
    if n_radii < 1 or margin_px < 0:
        raise ValueError(f"n_radii must be >= 1 and margin_px >= 0, got {n_radii}, {margin_px}")
    if views is None:
        view_list = tuple(make_views(cal).values())
    else:
        view_list = tuple(v if isinstance(v, View) else get_views(cal, v)[0] for v in views)
    mirrors = _mirrors_in_meas(cal)
    camera = cal.T_meas_cam[:3, 3].copy()  # camera centre in the measurement frame
    cos_max = np.cos(np.radians(max_incidence_deg))
    radial = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=-1)
    psi = theta if normal_angle_rad is None else np.asarray(normal_angle_rad, float).ravel()
    if psi.shape != theta.shape:
        raise ValueError(f"normal_angle_rad must have shape {theta.shape}, got {psi.shape}")
    normal = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=-1)
    w, h = cal.image_size
    radii = np.linspace(r0, r1, n_radii) if n_radii > 1 else (0.5 * (r0 + r1))[None]
    out = {}
    for view in view_list:
        ok = np.ones(theta.size, dtype=bool)
        for r in radii:
            pts = radial * r[:, None]
            path, leave = _path_ok(pts, camera, view.mirrors, mirrors, r)
            ok &= path & (np.einsum("ij,ij->i", leave, normal) > cos_max)
            uv = project_meas_points(pts, cal, view)
            with np.errstate(invalid="ignore"):
                ok &= (uv[:, 0] >= margin_px) & (uv[:, 0] <= w - 1 - margin_px) & \
                      (uv[:, 1] >= margin_px) & (uv[:, 1] <= h - 1 - margin_px)
        out[view.name] = ok
    return out
