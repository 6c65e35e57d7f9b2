"""The whole calibration (plan → render → camera, mirrors, laser plane, frame) on rendered
images of a half-resolution camera (640×512 pixels of 10.6 µm: the paper rig's field of view),
pinhole, 16 spp (24 for the small target's shots), a 9×7 × 4 mm target — small enough for CI.

Measured on this configuration (2026-12-01, 10 camera poses; laser boards seen directly and
in a mirror, boards in mirror shots refined by their image model, the line fitted as an image
model): fx −0.15 % (σ reported by OpenCV ~0.5 %: ten half-resolution images determine the
camera poorly), mirrors 0.014/0.053° and +110/+61 µm (the focal-length error scales every
depth), laser plane 0.026° and +121 µm, frame origin 0.14 mm (2026-11-23, all shots at 16 spp:
mirrors 0.014/0.060°, +130/+90 µm, laser 0.005°, +54 µm; earlier, with the laser boards seen
directly only: laser 0.14°, origin 0.35 mm).  The
tolerances below are two to five times those figures: they guard the pipeline (handedness,
corner order, frames, signs — an error there costs degrees and millimetres), not the accuracy
of the issue, which needs full resolution and more images (`lts360 calibrate`).
"""

from __future__ import annotations

import json
import tomllib
from importlib import resources

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="rendering the calibration images needs Mitsuba 3")
pytest.importorskip("cv2", reason="calibration needs OpenCV")


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.calibration_run import run_calibrate
    from lts360.scenes.rig_io import rig_from_dict, rig_to_toml
    from lts360.scenes.targets import Chessboard

    data = tomllib.loads(resources.files("lts360.scenes").joinpath("presets/paper.toml").read_text())
    data["camera"].update(width_px=640, height_px=512, pixel_pitch_um=10.6)
    rig_file = tmp_path_factory.mktemp("rig") / "half.toml"
    rig_file.write_text(rig_to_toml(rig_from_dict(data)))
    out = tmp_path_factory.mktemp("cal")
    report = run_calibrate(out, rig_name=str(rig_file), spp=16, target_spp=24, n_camera=10,
                           n_mirror=3, n_laser=3, board=Chessboard(squares_x=9, squares_y=7, square_mm=4.0,
                                                       margin_mm=2.0),
                           thin_lens=False, say=lambda *_: None)
    return out, report


def test_the_small_target_shots_are_rendered_with_their_own_spp(calibrated):
    out, report = calibrated
    truth = json.loads((out / "truth.json").read_text())
    spp = {b["name"]: b["spp"] for b in truth["boards"]}
    assert {v for k, v in spp.items() if k.startswith("camera")} == {16}
    assert {v for k, v in spp.items() if not k.startswith("camera")} == {24}
    assert report["settings"]["spp"] == 16 and report["settings"]["target_spp"] == 24


def test_outputs_are_written_and_loadable(calibrated):
    from lts360.recon.model import load_calibration

    out, report = calibrated
    cal = load_calibration(out / "calibration.json")
    assert cal.image_size == (640, 512)
    assert set(cal.mirror_names) == {"left", "right"}
    assert (out / "fig8.png").stat().st_size > 10_000
    saved = json.loads((out / "report.json").read_text())
    assert saved["camera"]["rms_px"] == pytest.approx(report["camera"]["rms_px"])
    unc = cal.uncertainty
    assert np.asarray(unc["mirrors"]["left"]["cov_abd"]).shape == (3, 3)
    assert unc["laser_plane"]["std_offset_mm"] > 0
    cam = unc["camera"]
    assert cam["std_method"] == "jackknife over boards"
    assert np.asarray(cam["cov"]).shape == (9, 9) and cam["cov_names"][:4] == ["fx", "fy", "cx", "cy"]
    assert cam["std"]["fx"] > 0 and cam["std_opencv"]["fx"] > 0
    # the optics it was made with, for the twin: the rig file given and its full TOML
    from lts360.twin.rig import twin_design

    assert cal.optics["rig"].endswith("half.toml")
    design = twin_design(cal)
    assert design.camera.width_px == 640 and design.camera.f_number == 2.8


def test_estimates_are_near_the_truth(calibrated):
    _, report = calibrated
    acc = report["accuracy"]
    assert report["camera"]["rms_px"] < 0.2
    assert abs(acc["camera"]["fx_rel_percent"]) < 0.5
    assert abs(acc["camera"]["cx_px"]) < 2.0 and abs(acc["camera"]["cy_px"]) < 2.0
    for name in ("left", "right"):
        assert acc["mirrors"][name]["lsq"]["normal_deg"] < 0.1, acc["mirrors"]
        assert abs(acc["mirrors"][name]["lsq"]["offset_um"]) < 700, acc["mirrors"]
    assert acc["laser_plane"]["normal_deg"] < 0.15, acc["laser_plane"]
    assert abs(acc["laser_plane"]["offset_um"]) < 300, acc["laser_plane"]
    # Every laser pose was solved from its direct and its mirror view.
    assert [len(v) for v in report["laser_plane"]["pose_views"]] == [2, 2, 2]
    assert np.linalg.norm(acc["measurement_frame"]["origin_um"]) < 700


def test_the_shots_fitted_on_two_threads_give_the_serial_result(calibrated, monkeypatch):
    """The mirror shots' boards and the laser lines are found shot by shot on two threads
    (``FIT_THREADS``): the same calibration as one after the other, up to OpenCV's
    multithreaded summation order (as below), the same shots kept and skipped."""
    import lts360.recon.calibration.from_images as fi

    out, _ = calibrated
    images = fi.read_calibration_images(out / "images")
    got = {}
    for n in (1, 2):
        monkeypatch.setattr(fi, "FIT_THREADS", n)
        got[n] = fi.calibrate_rig(images)
    a, b = got[1], got[2]
    assert a.skipped == b.skipped and list(a.laser_lines) == list(b.laser_lines)
    assert {k: v[0] for k, v in a.mirror_observations.items()} == \
        {k: v[0] for k, v in b.mirror_observations.items()}
    ca, cb = a.calibration, b.calibration
    np.testing.assert_allclose(ca.K, cb.K, rtol=1e-6)
    for ma, mb in zip(ca.mirrors, cb.mirrors):
        np.testing.assert_allclose(ma.n, mb.n, atol=1e-5)
        assert abs(ma.d_mm - mb.d_mm) < 1e-3
    np.testing.assert_allclose(ca.laser_plane[0], cb.laser_plane[0], atol=1e-5)
    assert abs(ca.laser_plane[1] - cb.laser_plane[1]) < 1e-3


@pytest.mark.slow
def test_the_images_folder_alone_reproduces_the_calibration(calibrated, tmp_path):
    """`--images DIR`: nothing rendered, the same result from the same files."""
    from lts360.experiments.calibration_run import run_calibrate
    from lts360.recon.model import load_calibration

    out, _ = calibrated
    report = run_calibrate(tmp_path, images_dir=out / "images", say=lambda *_: None)
    assert "accuracy" not in report  # no truth beside real images
    a, b = load_calibration(out / "calibration.json"), load_calibration(tmp_path / "calibration.json")
    # Same files, same numbers — up to OpenCV's multithreaded summation order: measured
    # differences of 1e-9 to 2e-7 in the normals between runs (1e-5 rad is 0.0006°).
    np.testing.assert_allclose(a.K, b.K, rtol=1e-6)
    np.testing.assert_allclose(a.laser_plane[0], b.laser_plane[0], atol=1e-5)
    assert abs(a.laser_plane[1] - b.laser_plane[1]) < 1e-3


@pytest.mark.slow
def test_a_camera_model_round_on_the_same_images(calibrated, tmp_path):
    """`--camera-model 1` through the whole pipeline: the camera boards' corners from the
    image model of their own squares fit Zhang's model far more tightly than SB's, and the
    calibration stays as near the truth as the tolerances above ask."""
    from lts360.experiments.calibration_run import run_calibrate
    from lts360.recon.model import load_calibration

    out, sb_report = calibrated
    report = run_calibrate(tmp_path, images_dir=out / "images", camera_model_rounds=1,
                           say=lambda *_: None)
    assert report["settings"]["camera_model_rounds"] == 1
    assert report["camera"]["rms_px"] < 0.5 * sb_report["camera"]["rms_px"]
    K_true = np.asarray(json.loads((out / "truth.json").read_text())["camera"]["K"])
    K = load_calibration(tmp_path / "calibration.json").K
    assert abs(K[0, 0] / K_true[0, 0] - 1) < 5e-3
    assert np.all(np.abs(K[:2, 2] - K_true[:2, 2]) < 2.0)


_SMALL = dict(spp=16, target_spp=24, n_camera=10, n_mirror=3, n_laser=3, thin_lens=False)


def _small_board():
    from lts360.scenes.targets import Chessboard

    return Chessboard(squares_x=9, squares_y=7, square_mm=4.0, margin_mm=2.0)


@pytest.mark.slow
def test_images_rendered_in_the_background_calibrate_as_a_sequential_run(calibrated, tmp_path):
    """`lts360 demo` renders the calibration images on a thread of its own while the main
    thread renders and measures frames (the two share a lock for their Mitsuba and Dr.Jit
    work): the same PNGs, byte for byte, as the sequential run (every shot has its own
    seed), and the same calibration from them."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from lts360.experiments.calibration_run import render_calibration, run_calibrate
    from lts360.recon.model import load_calibration
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    out, report = calibrated
    rig = report["settings"]["rig"]
    lock = threading.Lock()
    with ThreadPoolExecutor(max_workers=1) as pool:
        job = pool.submit(render_calibration, tmp_path, rig_name=rig, board=_small_board(),
                          say=lambda *_: None, bar=False, stop=threading.Event(), lock=lock,
                          **_SMALL)
        for seed in range(3):  # the main thread renders meanwhile
            with lock:
                simulate_frame(load_rig(rig), build_object("plug-gauge"), spp=4, seed=seed,
                               noise="realistic")
        shots = job.result()
    names = sorted(p.name for p in (out / "images").glob("*.png"))
    assert names and names == sorted(p.name for p in shots.images_dir.glob("*.png"))
    for name in names:
        assert (out / "images" / name).read_bytes() == (shots.images_dir / name).read_bytes(), name
    run_calibrate(tmp_path, rig_name=rig, rendered=shots, say=lambda *_: None, **_SMALL)
    a, b = load_calibration(out / "calibration.json"), load_calibration(tmp_path / "calibration.json")
    np.testing.assert_allclose(a.K, b.K, rtol=1e-6)  # OpenCV's threads: 1e-9-level differences
    np.testing.assert_allclose(a.laser_plane[0], b.laser_plane[0], atol=1e-5)


def test_a_stopped_background_render_leaves_no_images_folder(tmp_path):
    """The demo stops its background rendering when it fails: after the shot in hand, with
    :class:`RenderStopped`, and no ``images/`` that could pass for a finished set."""
    import threading

    from lts360.experiments.calibration_run import RenderStopped, render_calibration

    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    stop = threading.Event()
    stop.set()
    with pytest.raises(RenderStopped, match="stopped after camera-00"):
        render_calibration(tmp_path, rig_name="paper", board=_small_board(), say=lambda *_: None,
                           bar=False, stop=stop, **{**_SMALL, "spp": 1})
    assert not (tmp_path / "images").exists() and not (tmp_path / "truth.json").exists()
    assert len(list((tmp_path / ".images.partial").glob("*.png"))) == 1


def test_a_manifest_without_design_or_with_missing_images_fails_clearly(tmp_path):
    from lts360.recon.calibration.from_images import read_calibration_images

    with pytest.raises(ValueError, match="no manifest.json"):
        read_calibration_images(tmp_path)
    (tmp_path / "manifest.json").write_text(json.dumps({
        "board": {"pattern_size": [6, 5], "square_mm": 2.0},
        "shots": [{"name": "a", "kind": "camera", "image": "a.png"}]}))
    with pytest.raises(ValueError, match="image 'a.png' of shot 'a' is missing"):
        read_calibration_images(tmp_path)
    (tmp_path / "manifest.json").write_text(json.dumps({
        "board": {"pattern_size": [6, 5], "square_mm": 2.0},
        "shots": [{"name": "a", "kind": "selfie", "image": "a.png"}]}))
    with pytest.raises(ValueError, match="kind 'selfie'"):
        read_calibration_images(tmp_path)
