"""Score a measured cloud against the ground truth written beside rendered frames.

Frames of coordinates: a cloud's points are in the measurement frame with ``z`` = the stage
position of their section; for frames measured with the true calibration (``frame.json``) the
measurement frame is the world frame.  Moving the stage by ``z`` lowers the object by ``z``,
so the point ``(x, y, 0)`` seen at stage ``z`` is the point ``(x, y, z)`` of the object in its
un-staged placement: the cloud compares directly with ``SceneObject.mesh_world()``.

Errors are signed: positive outside the true surface.  Two truths: the analytic radius
``r(θ, z)`` (exact, float64) where the object has one, and the point-to-mesh distance
(Open3D's ``RaycastingScene``; float32 inside, ~1 µm resolution at these sizes).
"""

from __future__ import annotations

import numpy as np

from lts360.folders import first_frame_meta
from lts360.geometry.fit import fit_circle
from lts360.recon.triangulation.cloud import VIEW_NAMES, Cloud
from lts360.recon.triangulation.reject import rejection_counts
from lts360.scenes.frame_truth import load_truth
from lts360.scenes.objects import SceneObject

__all__ = ["true_radius_band", "load_truth", "load_rig_truth", "signed_mesh_distance",
           "score_cloud", "error_stats", "measurable"]


def measurable(points_mm: np.ndarray, view_codes: np.ndarray, obj: SceneObject, rig_truth: dict,
               *, clearance_mm: float = 1e-4) -> np.ndarray:
    """Whether the *true* surface point at each measured point's (θ, z) could be measured by the
    point's view: seen by that view's (virtual) camera and lit by the laser (directly or through
    a mirror), with the object mesh as the only occluder (Open3D ray casting).

    A point measured where this is false is *spurious*: the true surface there is hidden (the
    valleys between a cable's strands, the inside of a groove) and the detector found the
    sheet's tail on a neighbouring flank.  Such θ are missing coverage, not measurement error.

    ``rig_truth`` is a frame's ``frame.json`` (camera centre, mirror planes, laser apex, world
    frame).  Points are in the un-staged object placement (see the module docstring), so the
    rig is moved by each point's ``z``.
    """
    import open3d as o3d

    from lts360.geometry.mirror import reflect_points

    pts = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    if obj.radius_fn is None or len(pts) == 0:
        return np.ones(len(pts), bool)
    T = obj.T_world_object
    local = obj.to_object_frame(pts)
    th = np.arctan2(local[:, 1], local[:, 0])
    r = obj.true_radius_at(pts)
    ok = np.isfinite(r)
    radial = np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
    surf_local = radial * np.where(ok, r, 0.0)[:, None] + np.column_stack(
        [np.zeros((len(pts), 2)), local[:, 2]])
    start = (surf_local + radial * 0.005) @ T[:3, :3].T + T[:3, 3]  # 5 µm outside the surface
    z = pts[:, 2:3] * np.array([[0.0, 0.0, 1.0]])
    mirrors = {m["name"]: (np.asarray(m["n"], float), float(m["d"])) for m in rig_truth["mirrors"]}
    cam = np.asarray(rig_truth["camera"]["center_mm"], float)
    apex = np.asarray(rig_truth["laser"]["origin_mm"], float)

    def virtual(p, seq):
        p = p.reshape(1, 3)
        for name in seq:
            p = reflect_points(p, *mirrors[name])
        return p.ravel()

    scene = o3d.t.geometry.RaycastingScene()
    mesh = obj.mesh_world()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))

    def clear(targets: np.ndarray) -> np.ndarray:
        d = targets - start
        dist = np.linalg.norm(d, axis=1)
        u = d / dist[:, None]
        rays = np.concatenate([start, u], axis=1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        return ~((hit > clearance_mm) & (hit < dist))

    names = {code: VIEW_NAMES.get(int(code), str(code)) for code in np.unique(view_codes)}
    seen = np.zeros(len(pts), bool)
    for code, name in names.items():
        m = view_codes == code
        seq = () if name == "direct" else tuple(name.split("-"))
        if not all(s in mirrors for s in seq):
            seen[m] = True
            continue
        # The view's camera as seen from the point: the camera mirrored through the mirrors in
        # the reverse order of the path (point → first mirror → ... → camera).
        centre = virtual(cam, seq[::-1]) if seq else cam
        seen[m] = _clear_subset(clear, centre, z, m)[m]
    lit = np.zeros(len(pts), bool)
    for seq in [(), *[(n,) for n in mirrors]]:
        lit |= _clear_subset(clear, virtual(apex, seq) if seq else apex, z, np.ones(len(pts), bool))
    return ok & seen & lit


def _clear_subset(clear, centre: np.ndarray, z: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``clear`` towards ``centre`` (moved by each point's z) for the masked points."""
    return clear(centre[None, :] + z) & mask


def true_radius_band(obj: SceneObject, zs, margin_mm: float = 1.0) -> tuple[float, float]:
    """The radii the object's surface spans over the heights ``zs`` (about the axis), widened
    by ``margin_mm``: a search band taken from the truth, for tests and studies that isolate
    the detector from the band search (``lts360 measure`` finds its band in the image)."""
    th = np.linspace(-np.pi, np.pi, 1441)
    T, Z = np.meshgrid(th, np.asarray(zs, dtype=float))
    r = obj.radius_fn(T.ravel(), Z.ravel())
    r = r[np.isfinite(r)]
    return max(0.5, float(r.min()) - margin_mm), float(r.max()) + margin_mm


def load_rig_truth(truth_dir) -> dict:
    """The ``frame.json`` of a frame directory, or of the first section of a scan directory."""
    return first_frame_meta(truth_dir)


def signed_mesh_distance(mesh, points_mm: np.ndarray) -> np.ndarray:
    """Signed distance (mm, positive outside) from points to a watertight mesh (Open3D)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    q = o3d.core.Tensor(np.asarray(points_mm, dtype=np.float32))
    return scene.compute_signed_distance(q).numpy().astype(float)


def error_stats(err_mm: np.ndarray) -> dict:
    err = np.asarray(err_mm, dtype=float)
    err = err[np.isfinite(err)]
    if err.size == 0:
        return {"n": 0, "rms_mm": None, "mean_mm": None, "std_mm": None, "max_abs_mm": None,
                "p95_mm": None}
    return {"n": int(err.size), "rms_mm": float(np.sqrt(np.mean(err**2))),
            "mean_mm": float(err.mean()), "std_mm": float(err.std()),
            "max_abs_mm": float(np.abs(err).max()), "p95_mm": float(np.percentile(np.abs(err), 95))}


def _coverage_deg(theta: np.ndarray, section: np.ndarray, bin_deg: float) -> float:
    """Mean over sections of the angle covered by valid points.

    Each point covers the arc to its next neighbour (sorted, periodic) up to ``bin_deg``: a
    cloud sampled every ``bin_deg`` or finer covers 360°, a gap wider than ``bin_deg`` counts
    as uncovered except for one ``bin_deg``.
    """
    if theta.size == 0:
        return 0.0
    out = []
    for s in np.unique(section):
        t = np.sort(np.degrees(theta[section == s]) % 360.0)
        gaps = np.diff(np.append(t, t[0] + 360.0))
        out.append(float(np.minimum(gaps, bin_deg).sum()))
    return float(np.mean(out))


def _object_theta(obj: SceneObject, pts: np.ndarray) -> np.ndarray:
    """θ of points about the object's own axis (its frame)."""
    if not len(pts):
        return np.zeros(0)
    local = obj.to_object_frame(pts)
    return np.arctan2(local[:, 1], local[:, 0])


def score_cloud(cloud: Cloud, obj: SceneObject, *, theta_bin_deg: float = 0.5,
                use_mesh: bool = True, rig_truth: dict | None = None) -> dict:
    """Metrics of a cloud against an object's truth (see module docstring).

    With ``rig_truth`` (a frame's ``frame.json``), points whose true surface point is hidden
    from their view or unlit (:func:`measurable`) are *spurious*: they are counted and scored
    apart (``n_spurious``, ``spurious``) and left out of the error statistics and the coverage,
    so that occlusions show as missing coverage, not as error; ``all_points`` keeps the
    statistics of every valid point.
    """
    valid = cloud.valid
    # Rows rejected by a truth-free criterion of the measurement (quality flags), beside the
    # truth-aware "spurious" count below.
    rejected = rejection_counts(cloud.quality)
    c = cloud.select(valid)
    pts = c.points_mm
    analytic = obj.radial_error(pts) if obj.radius_fn is not None else np.full(len(pts), np.nan)
    mesh_err = signed_mesh_distance(obj.mesh_world(), pts) if use_mesh and len(pts) else \
        np.full(len(pts), np.nan)
    primary = analytic if np.isfinite(analytic).any() else mesh_err
    extra = {}
    if rig_truth is not None and len(pts):
        keep = measurable(pts, c.view, obj, rig_truth)
        extra = {"n_spurious": int((~keep).sum()), "spurious": error_stats(primary[~keep]),
                 "all_points": error_stats(primary)}
        c, pts = c.select(keep), pts[keep]
        analytic, mesh_err, primary = analytic[keep], mesh_err[keep], primary[keep]
    # Coverage is of the object's surface: θ about the object's own axis (an object off the
    # measurement axis is seen over a narrower θ about that axis).
    theta_obj = _object_theta(obj, pts)
    out = {"object": obj.spec, "n_points": int(len(pts)), "n_theta_samples": int(len(cloud)),
           "truth": "analytic r(θ, z)" if np.isfinite(analytic).any() else "mesh distance",
           "coverage_deg": _coverage_deg(theta_obj, c.section, theta_bin_deg),
           "rejected": rejected, **extra}
    out.update(error_stats(primary))
    out["mesh_distance"] = error_stats(mesh_err)
    out["analytic"] = error_stats(analytic)
    rows = {}
    for code in np.unique(c.view):
        m = c.view == code
        row = error_stats(primary[m])
        row["coverage_deg"] = _coverage_deg(theta_obj[m], c.section[m], theta_bin_deg)
        rows[VIEW_NAMES.get(int(code), str(code))] = row
    out["views"] = rows
    # Round objects: a circle per section (in the object frame) and the radius bias.
    if obj.radius_fn is not None and len(pts) >= 3:
        local = obj.to_object_frame(pts)
        fits = []
        for s in np.unique(c.section):
            m = c.section == s
            if m.sum() < 10:
                continue
            z = float(np.median(local[m, 2]))
            th = np.linspace(-np.pi, np.pi, 720, endpoint=False)
            r_true = obj.radius_fn(th, np.full_like(th, z))
            if not np.all(np.isfinite(r_true)) or np.ptp(r_true) > 1e-9:
                continue  # not a full circle at this height
            fit = fit_circle(local[m, :2])
            fits.append({"section": int(s), "z_mm": z, "diameter_mm": 2 * fit.radius_mm,
                         "radius_bias_mm": fit.radius_mm - float(r_true[0]),
                         "center_mm": fit.center_mm.tolist(), "fit_rms_mm": fit.rms_mm})
        if fits:
            out["circle_fits"] = fits
            out["fitted_diameter_mm"] = float(np.mean([f["diameter_mm"] for f in fits]))
            out["radius_bias_mm"] = float(np.mean([f["radius_bias_mm"] for f in fits]))
    return out
