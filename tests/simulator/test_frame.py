"""Rendered frames on disk: files, exact truth in frame.json, determinism, the CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")

from lts360.folders import read_image as read_png
from lts360.geometry import project_points  # noqa: E402
from lts360.scenes.objects import build_object  # noqa: E402
from lts360.scenes.rig_io import load_rig  # noqa: E402
from lts360.simulator.io import read_exr  # noqa: E402


@pytest.fixture(scope="module")
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")


def test_frame_directory_holds_image_radiance_truth(variant, tmp_path):
    from lts360.simulator.frame import simulate_frame, write_frame

    rig = load_rig("paper")
    obj = build_object("plug-gauge:x=0.3,tilt_deg=1")
    frame = simulate_frame(rig, obj, spp=8, seed=5, noise="realistic", scale=0.25, z_mm=1.5)
    out = write_frame(tmp_path / "f", frame)
    assert sorted(p.name for p in out.iterdir()) == ["frame.json", "image.png", "radiance.exr",
                                                     "truth.ply"]
    img = read_png(out / "image.png")
    assert img.dtype == np.uint8 and img.shape == (256, 320)
    exr = read_exr(out / "radiance.exr")
    assert set(exr) == {"Y", "laser"} and exr["Y"].dtype == np.float32
    assert np.array_equal(exr["Y"], frame.render.radiance_W_m2_sr)
    truth = json.loads((out / "frame.json").read_text())
    K = np.array(truth["camera"]["K"])
    assert truth["camera"]["image_size"] == [320, 256]
    assert K[0, 2] == pytest.approx((639.5 + 0.5) * 0.25 - 0.5)
    R, t = np.array(truth["camera"]["R"]), np.array(truth["camera"]["t"])
    assert np.allclose(R, rig.camera.R) and np.allclose(t, rig.camera.t_mm)
    for m_json, m in zip(truth["mirrors"], rig.mirrors):
        assert np.allclose(m_json["n"], m.normal) and m_json["d"] == pytest.approx(m.d_mm)
        assert np.allclose(m_json["corners"], m.corners_mm)
    assert truth["laser"]["plane"]["n"] == [0.0, 0.0, 1.0] and truth["laser"]["plane"]["d"] == 0.0
    assert truth["stage"]["z_mm"] == 1.5 and truth["sensor"]["noise"] == "realistic"
    assert truth["render"]["seed"] == 5 and truth["object"]["spec"] == obj.spec
    # The truth mesh is the object as rendered: placed, and moved down by the stage.
    import trimesh

    mesh = trimesh.load(out / "truth.ply")
    T = np.array(truth["object"]["T_world_object"])
    assert np.allclose(mesh.vertices, obj.mesh_object.vertices @ T[:3, :3].T + T[:3, 3], atol=1e-4)
    # The stripe lies where the truth says. The axis (tilted 1° towards +X, lowered 1.5 mm by
    # the stage) crosses z = 0 at x = 0.3 + 1.5·tan 1°; the section is a circle to 1.5 µm.
    r = obj.params["diameter_mm"] / 2
    cx = 0.3 + 1.5 * np.tan(np.radians(1.0))
    th = np.radians(np.linspace(-130, -50, 40))  # the direct view, away from grazing ends
    world = np.column_stack([cx + r * np.cos(th), r * np.sin(th), np.zeros_like(th)])
    uv = project_points(world, K, truth["camera"]["dist"], R, t)
    rad = exr["laser"].astype(float)
    offsets = []
    for u, v in uv:  # laser-weighted centroid in a 7×7 window around each projected point
        iu, iv = int(round(u)), int(round(v))
        win = rad[iv - 3:iv + 4, iu - 3:iu + 4]
        assert win.sum() > 0
        gy, gx = np.mgrid[iv - 3:iv + 4, iu - 3:iu + 4]
        offsets.append(np.hypot((win * gx).sum() / win.sum() - u, (win * gy).sum() / win.sum() - v))
    # At 1/4 scale the stripe is ~0.5 px wide and 8 spp leave Monte Carlo noise: 0.5 px.
    assert np.median(offsets) < 0.5


def test_same_seed_same_noisy_image(variant):
    from lts360.simulator.frame import simulate_frame

    rig = load_rig("paper")
    obj = build_object("plug-gauge")
    a = simulate_frame(rig, obj, spp=1, seed=3, noise="realistic", scale=0.125).image
    b = simulate_frame(rig, obj, spp=1, seed=3, noise="realistic", scale=0.125).image
    c = simulate_frame(rig, obj, spp=1, seed=4, noise="realistic", scale=0.125).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_laser_off_is_dark_and_ambient_lights_the_scene(variant):
    from lts360.simulator.frame import simulate_frame

    rig = load_rig("paper")
    obj = build_object("plug-gauge")
    off = simulate_frame(rig, obj, spp=1, seed=1, noise="none", scale=0.125, laser_on=False,
                         exposure_time_s=1e-3)
    assert off.render.radiance_W_m2_sr.max() == 0.0
    assert off.image.max() <= rig.sensor.dark_offset_dn + 1
    lit = simulate_frame(rig, obj, spp=1, seed=1, noise="none", scale=0.125, laser_on=False,
                         ambient="bright", exposure_time_s=2e-6)
    assert lit.render.laser_W_m2_sr.max() == 0.0 and lit.render.radiance_W_m2_sr.max() > 0


def test_render_cli_scan_and_bad_input(variant, tmp_path):
    cmd = [sys.executable, "-m", "lts360.cli", "render", "--object", "plug-gauge",
           "--out", str(tmp_path / "scan"), "--spp", "1", "--scale", "0.125", "--sections", "3",
           "--pitch-mm", "0.68"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    scan = json.loads((tmp_path / "scan" / "scan.json").read_text())
    assert [s["z_mm"] for s in scan["sections"]] == pytest.approx([-0.68, 0.0, 0.68])
    for s in scan["sections"]:
        assert (tmp_path / "scan" / s["dir"] / "frame.json").exists()
    bad = subprocess.run(cmd[:-4] + ["--spp", "0"], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "--spp" in bad.stderr
    bad = subprocess.run(cmd[:6] + ["--out", str(tmp_path / "x"), "--variant", "nonsense_mono"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--variant" in bad.stderr
    assert not (tmp_path / "x").exists()


def test_scalar_variant_renders_a_tiny_frame():
    """The integrator also runs per sample in a scalar variant (slow: tiny images only)."""
    code = ("import mitsuba as mi, numpy as np; mi.set_variant('scalar_rgb');"
            "from lts360.scenes.rig_io import load_rig; from lts360.scenes.objects import build_object;"
            "from lts360.simulator.scene import SceneSpec, object_meshes;"
            "from lts360.simulator.render import render_radiance;"
            "r = render_radiance(SceneSpec(load_rig('paper'), object_meshes(build_object('plug-gauge'))),"
            " spp=1, scale=0.05); print(r.radiance_W_m2_sr.shape, float(r.laser_W_m2_sr.max()) > 0)")
    if "scalar_rgb" not in mi.variants():
        pytest.skip("this Mitsuba build has no scalar_rgb variant")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "(51, 64) True" in proc.stdout


def test_frame_rendered_on_a_pixel_window(variant):
    # Only the listed pixels are rendered (the rest is dark); their values have the statistics
    # of a full render's (another Monte Carlo realisation of the same expectation).
    from lts360.simulator.frame import simulate_frame

    rig = load_rig("paper")
    obj = build_object("plug-gauge")
    full = simulate_frame(rig, obj, spp=16, seed=2, noise="none", scale=0.25)
    lit = np.argwhere(full.render.laser_W_m2_sr > 0)[:, ::-1]  # (x, y) of the stripe
    ys, xs = np.mgrid[0:full.image.shape[0], 0:full.image.shape[1]]
    near = np.zeros(full.image.shape, bool)
    near[lit[:, 1], lit[:, 0]] = True
    from scipy.ndimage import binary_dilation

    near = binary_dilation(near, iterations=3)
    px = np.column_stack([xs[near], ys[near]])
    win = simulate_frame(rig, obj, spp=16, seed=2, noise="none", scale=0.25, pixels_xy=px)
    assert win.truth["render"]["pixels"] == len(px)
    assert np.all(win.render.radiance_W_m2_sr[~near] == 0)
    a, b = full.render.laser_W_m2_sr[near], win.render.laser_W_m2_sr[near]
    # The stripe's total laser radiance agrees to the Monte Carlo noise of 16 spp: the ratio of
    # two full frames' totals (other seeds) scatters with sd 1.4 % at this scale (8 seed pairs,
    # 2026-12-05), so 3 sd.
    assert abs(b.sum() / a.sum() - 1.0) < 0.045
    assert np.corrcoef(a, b)[0, 1] > 0.95
    with pytest.raises(ValueError, match="inside"):
        simulate_frame(rig, obj, spp=1, seed=2, noise="none", scale=0.25,
                       pixels_xy=np.array([[10_000, 0]]))
