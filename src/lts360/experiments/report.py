"""Text reports of rigs and coverage, shared by the CLI and the demo."""

from __future__ import annotations

__all__ = ["format_rig", "format_coverage", "format_windows"]


def format_windows(windows) -> str:
    return ", ".join(f"[{a:7.1f}°, {b:7.1f}°]" for a, b in windows) or "—"


def format_rig(rig) -> str:
    """Human-readable summary of a rig."""
    lines = []
    add = lines.append
    cam, las = rig.camera, rig.laser
    d = rig.design
    add(f"rig {rig.name}")
    if d is not None:
        add(f"  design: alpha {d.alpha_deg:g}°, beta {d.beta_deg:g}°, camera {d.camera_distance_mm:g} mm, "
              f"laser {d.laser_distance_mm:g} mm, mirror corner {d.mirror_corner_distance_mm:g} mm, "
              f"mirrors {d.mirror_width_mm:g}×{d.mirror_height_mm:g} mm")
    c = cam.center_mm
    add(f"  camera: {cam.width_px}×{cam.height_px} px, {cam.pixel_pitch_um:g} µm, f = {cam.focal_length_mm:g} mm,"
          f" f/{cam.f_number:g}, focus {cam.focus_distance_mm:g} mm, centre ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) mm")
    add(f"  laser: {las.wavelength_nm:g} nm, {las.power_mW:g} mW, fan {las.fan_angle_deg:g}°, "
          f"waist {las.waist_um:g} µm, z_R {las.rayleigh_range_mm:g} mm (M² {las.m_squared:.2f}), "
          f"apex ({las.origin_mm[0]:.1f}, {las.origin_mm[1]:.1f}, {las.origin_mm[2]:.1f}) mm")
    for m in rig.mirrors:
        n = m.normal
        add(f"  mirror {m.name}: n = ({n[0]:.4f}, {n[1]:.4f}, {n[2]:.4f}), d = {m.d_mm:.3f} mm, "
              f"{m.width_mm:g}×{m.height_mm:g} mm, R = {m.reflectance:g}")
    return "\n".join(lines)


def format_coverage(rig, cov) -> str:
    """Per-view θ windows, overlaps and total coverage as a table."""
    lines = []
    add = lines.append
    add(f"coverage of a Ø{2 * cov.radius_mm:g} mm section (θ step {cov.step_deg:g}°):")
    add(f"  {'view':12s} {'measured':>9s}  θ windows")
    for view in cov.views():
        add(f"  {view:12s} {cov.measured_deg(view):8.1f}°  {format_windows(cov.windows(view))}")
    views = [v for v in cov.views() if cov.measured[v].any()]
    for i, a in enumerate(views):
        for b in views[i + 1:]:
            ov = cov.overlap_deg(a, b)
            if ov > 0:
                add(f"  overlap {a}/{b}: {ov:.1f}°")
    add(f"  total: {cov.coverage_deg:.1f}° of 360°; image margin "
          f"{cov.image_margin_px(rig.camera.image_size):.0f} px")
    return "\n".join(lines)
