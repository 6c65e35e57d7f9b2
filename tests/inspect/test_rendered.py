"""End to end on rendered frames: render, measure with the true calibration and the digital
twin's bias correction, inspect against the analytic nominal with the truth beside, and
compare with ``lts360 score`` (slow: two renders and their twins)."""

import json

import pytest

from lts360.cli import main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def inspected(tmp_path_factory):
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    root = tmp_path_factory.mktemp("rendered")
    out = {}
    for spec, radius, material in (("pvc-pipe", 16.0, "white-pvc"),
                                   ("alu-pipe", 11.0, "machined-aluminium")):
        d = root / spec
        frame, cal = d / "frame", str(d / "frame" / "frame.json")
        assert main(["render", "--object", spec, "--out", str(frame), "--spp", "8",
                     "--noise", "none"]) == 0
        assert main(["measure", str(frame), "--calibration", cal, "--out", str(d / "cloud.ply"),
                     "--radius-mm", str(radius), "--bias-model", "twin",
                     "--twin-material", material]) == 0
        assert main(["score", str(d / "cloud.ply"), "--truth", str(frame), "--out",
                     str(d / "metrics.json")]) == 0
        rc = main(["inspect", str(d / "cloud.ply"), "--out", str(d / "report"), "--nominal",
                   spec, "--tolerance-mm", "0.2", "--truth", str(frame), "--calibration", cal])
        data = json.loads((d / "report" / "inspection.json").read_text())
        assert rc == (0 if data["verdict"]["pass"] else 1)  # a FAIL is exit 1
        out[spec] = (data["sections"][0], json.loads((d / "metrics.json").read_text()))
    return out


def test_the_diameter_error_is_twice_the_scored_radial_bias(inspected):
    for spec, (s, m) in inspected.items():
        err = s["d_ls_mm"]["value"] - s["truth"]["d_ls_mm"]
        # the LS fit weighs the directions evenly, the score's mean every point: 3 µm apart
        assert err == pytest.approx(2 * m["mean_mm"], abs=0.003), spec
    # twin-corrected, the PVC pipe's diameter is right within its own U; the shiny alu pipe's
    # is not (its axial waviness on a specular surface, which the straight twin of one section
    # does not model; docs/inspection.md).  This fixture (8 spp, one frame each) measured on
    # 2026-12-04: PVC +0.1 µm, U 4.0 µm; alu −22.2 µm, and −22.17 µm (U 3.7 µm, A3 +0.4 µm)
    # rendered with one bounce, the render's default (`--max-scatter auto`) for its machined
    # aluminium since.  U is bounded, so that a U grown to cover any error fails.
    pvc = inspected["pvc-pipe"][0]
    assert abs(pvc["d_ls_mm"]["value"] - pvc["truth"]["d_ls_mm"]) <= pvc["d_ls_mm"]["U_k2"]
    # U(D LS) of one noise-free section is ~4 µm (scatter, τ ≈ 2, the twin's inputs); 10 µm
    # would hide a real miss of the twin correction (~20 µm on the alu pipe)
    assert pvc["d_ls_mm"]["U_k2"] < 0.010
    alu = inspected["alu-pipe"][0]
    assert -0.035 < alu["d_ls_mm"]["value"] - alu["truth"]["d_ls_mm"] < -0.008


def test_pvc_ovality_and_alu_lobes(inspected):
    pvc, alu = inspected["pvc-pipe"][0], inspected["alu-pipe"][0]
    # each within its own U(k=2) (this fixture, 8 spp, 2026-12-04: ovality +25 µm, U 56 µm,
    # the 150 UPR default filter and the extremes' noise bias in U; A3 +0.8 µm, U 2.1 µm)
    e_ov = pvc["ovality_mm"]["value"] - pvc["truth"]["ovality_mm"]
    assert abs(e_ov) <= pvc["ovality_mm"]["U_k2"] and abs(e_ov) < 0.05
    assert alu["harmonics"]["dominant_order"] == 3
    e_a3 = alu["harmonics"]["a3_mm"]["value"] - alu["truth"]["a3_mm"]
    assert abs(e_a3) <= alu["harmonics"]["a3_mm"]["U_k2"] and abs(e_a3) < 0.002


def test_the_deviation_from_the_nominal_agrees_with_the_score(inspected):
    for spec, (s, m) in inspected.items():
        # normal distance after centring vs radial error about the true axis
        assert s["nominal"]["deviation_rms_mm"] == pytest.approx(m["rms_mm"], rel=0.25), spec
    # the PVC pipe's deviations lie inside ±0.1 mm but for a few points at the direct view's
    # grazing end (θ ≈ −156°), which at 8 spp reach −0.09 to −0.12 mm with the render's noise
    # realisation (measured 2026-12-04: −0.088 mm on a full frame, −0.117 mm, 3 of 4235
    # points, on the pixel-support frame); the shiny alu pipe's extremes (−40 µm lobes of
    # error where its specular lobe glints, ±120 µm single points) reach the band's edge too
    pvc = inspected["pvc-pipe"][0]
    assert pvc["nominal"]["n_outside"] <= 0.001 * pvc["n_valid"]
    assert pvc["nominal"]["deviation_min_mm"]["value"] > -0.15
    alu = inspected["alu-pipe"][0]
    assert alu["nominal"]["n_outside"] < 0.005 * alu["n_valid"]


@pytest.fixture(scope="module")
def alu_scan(tmp_path_factory):
    """The alu pipe's crest (z = 0, its waviness curving 0.16 /mm along the axis) in a scan of
    five sections 0.5 mm apart, measured with the twin shaped along the axis and straight."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    d = tmp_path_factory.mktemp("alu-scan")
    scan, cal = d / "scan", str(d / "scan" / "section_0000" / "frame.json")
    assert main(["render", "--object", "alu-pipe", "--out", str(scan), "--spp", "8",
                 "--noise", "none", "--sections", "5", "--pitch-mm", "0.5"]) == 0
    out = {}
    for name, axial in (("loft", "1.0"), ("prism", "0")):
        cloud = d / f"{name}.ply"
        assert main(["measure", str(scan), "--calibration", cal, "--out", str(cloud),
                     "--bias-model", "twin", "--twin-material", "machined-aluminium",
                     "--twin-axial-mm", axial]) == 0
        assert main(["inspect", str(cloud), "--out", str(d / name), "--truth", str(scan)]) == 0
        out[name] = json.loads((d / name / "inspection.json").read_text())["sections"]
    return out


def test_the_twin_shaped_along_the_axis_measures_the_wavy_pipe_within_its_u(alu_scan):
    """Straight, the twin leaves the crest's diameter off by more than 12 µm (the specular
    surface curved along the axis spreads the sheet's light unlike a prism); shaped by its
    neighbours' profiles (two passes) it is within its own U, and that U is well below the
    error it removed (a U that would also cover the straight twin's error says nothing).
    This fixture, 8 spp, 5 sections, 2026-12-05: the crest +4.5 µm, U 10.0 µm (the points'
    scatter about the circle, 9.7 µm, sets it), straight −18.2 µm.  Not every section is
    within its U: at z = 0.5 mm −10.6 µm against 7.1 µm (one twin of all views' points read
    −9.8 µm there)."""
    crest = {k: next(s for s in v if abs(s["z_mm"]) < 1e-6) for k, v in alu_scan.items()}
    err = {k: s["d_ls_mm"]["value"] - s["truth"]["d_ls_mm"] for k, s in crest.items()}
    assert err["prism"] < -0.012  # what there is to correct
    assert abs(err["loft"]) <= crest["loft"]["d_ls_mm"]["U_k2"]
    assert crest["loft"]["d_ls_mm"]["U_k2"] < 0.6 * abs(err["prism"])
    assert abs(err["loft"]) < 0.35 * abs(err["prism"])


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    """Small realistic scans (the coverage study's smaller set, STUDIES.md "Inspection under
    noise"): the PVC pipe (oval, dented) and the plug gauge, 4 sections 1 mm apart each, 8 spp,
    realistic sensor noise, measured with the true calibration, inspected with the truth."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    root = tmp_path_factory.mktemp("realistic")
    out = {}
    for spec in ("pvc-pipe", "plug-gauge"):
        d = root / spec
        scan = d / "scan"
        assert main(["render", "--object", spec, "--out", str(scan), "--spp", "8", "--noise",
                     "realistic", "--sections", "4", "--pitch-mm", "1", "--seed", "7"]) == 0
        assert main(["measure", str(scan), "--calibration",
                     str(scan / "section_0000" / "frame.json"), "--out",
                     str(d / "cloud.ply")]) == 0
        assert main(["inspect", str(d / "cloud.ply"), "--out", str(d / "r"), "--truth",
                     str(scan)]) == 0  # no tolerance: no verdict, exit 0
        out[spec] = json.loads((d / "r" / "inspection.json").read_text())
    return out


def test_realistic_extremes_lie_within_their_u(realistic):
    """D min, D max, ovality and RONt against the four circles within U(k = 2) of the truth:
    8 sections × 7 values; the study's target is 95 % (STUDIES.md); on 56 values allow 3
    outside (a 95 % coverage gives ≤ 3 outside with 70 % probability, ≤ 5 with 95 %: 5).
    A MICI resting on a gap's chord is not reported (None, with the section's warning): at
    most one such on these near-closed profiles."""
    out, undetermined = [], 0
    for data in realistic.values():
        for s in data["sections"]:
            t = s["truth"]
            for k in ("d_min_mm", "d_max_mm", "ovality_mm"):
                out.append(abs(s[k]["value"] - t[k]) <= s[k]["U_k2"])
            for ref in ("LSCI", "MZCI", "MCCI", "MICI"):
                v = s["ront_mm"][ref]["value"]
                if v is None:
                    assert ref == "MICI" and any("MICI" in w for w in s["warnings"])
                    undetermined += 1
                    continue
                out.append(abs(v - t["ront_mm"][ref]) <= s["ront_mm"][ref]["U_k2"])
    assert len(out) + undetermined == 56 and undetermined <= 1
    assert sum(not x for x in out) <= 5


def test_no_false_lump_on_the_gauge_and_the_axis_of_a_short_scan(realistic):
    g = realistic["plug-gauge"]["scan"]
    assert g["events"] == []  # a plain gauge has no lump and no neck-down
    for data in realistic.values():
        ax = data["scan"]["axis"]
        # the renders stand upright: the tilt is 0, within 0.05°, or "too short to tell"
        assert ax["tilt_deg"] is None and "too short" in ax["note"] or abs(ax["tilt_deg"]) < 0.05
        # 4 sections, 4 mm: no wavelength but the 2 mm one fits twice
        spec = data["scan"]["diameter_spectrum"]
        assert spec["dominant_wavelength_mm"] in (None, pytest.approx(2.0))


@pytest.fixture(scope="module")
def dent50(tmp_path_factory):
    """A 50 µm dent over σ = 2 mm of arc and 2 mm along z on the realistic PVC pipe (oval
    0.8 mm), 5 sections 2.5 mm apart centred on it, 8 spp, realistic noise, measured with the
    true calibration: what the arc-matched detector is for (STUDIES.md "Inspection under
    noise": D min alone cannot show it)."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    d = tmp_path_factory.mktemp("dent50")
    scan = d / "scan"
    assert main(["render", "--object", "pvc-pipe:dent=0.05,dent_sigma_arc_mm=2,dent_sigma_z_mm=2",
                 "--out", str(scan), "--spp", "8", "--noise", "realistic", "--sections", "5",
                 "--pitch-mm", "2.5", "--seed", "11"]) == 0
    assert main(["measure", str(scan), "--calibration", str(scan / "section_0000" / "frame.json"),
                 "--out", str(d / "cloud.ply")]) == 0
    assert main(["inspect", str(d / "cloud.ply"), "--out", str(d / "r")]) == 0
    return json.loads((d / "r" / "inspection.json").read_text())


def test_a_50_um_dent_over_2_mm_of_arc_is_found_and_nothing_else(dent50, realistic):
    """The dent, at its z and θ (−90°), its depth within its U of 50 µm less what the reference
    (the sections ≥ 5 mm away: 0.2 µm of it) holds; no other local event on the scan, and none
    on the plug gauge's 4 smooth realistic sections."""
    ev = dent50["scan"]["local_events"]
    assert [(e["kind"], e["z_extreme_mm"]) for e in ev] == [("dent", 0.0)], ev
    e = ev[0]
    assert abs(e["theta_deg"] + 90.0) <= 3.0
    assert abs(-e["depth_mm"] - 0.050) <= e["U_k2_mm"]
    assert e["p_noise"] < dent50["scan"]["local_events_settings"]["false_event_rate"]
    assert realistic["plug-gauge"]["scan"]["local_events"] == []
