"""The report: files, units in the JSON names, one CSV row per section, nothing half-written,
and the HTML page opened in a real headless browser."""

import csv
import json
import os
import shutil
import subprocess

import numpy as np
import pytest
from _profiles import scan_cloud

from lts360.inspect.nominal import ToleranceBand, load_nominal
from lts360.inspect.report import FIGURES, write_report
from lts360.inspect.run import inspect_cloud


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    cloud = scan_cloud(n_sections=6, dent_mm=0.1, dent_z_mm=0.34, noise_mm=0.001)
    ins = inspect_cloud(cloud, nominal=load_nominal("plug-gauge:d=20"),
                        band=ToleranceBand.symmetric(0.08), source="synthetic.ply")
    # long unbroken values, as a scan's truth spec or a deep path: they must wrap
    ins.data["command"] = "lts360 inspect " + "/very/long/unbroken/path" * 12 + "/cloud.ply"
    ins.data["truth"] = {"object": "pvc-pipe:" + ",".join(f"p{i}=0.123456789" for i in range(30)),
                         "analytic": True}
    return write_report(ins, tmp_path_factory.mktemp("r") / "report")


def test_files_json_and_csv(report_dir):
    names = {p.name for p in report_dir.iterdir()}
    assert names == {"inspection.json", "sections.csv", "report.html", *FIGURES}
    data = json.loads((report_dir / "inspection.json").read_text())
    s = data["sections"][0]
    assert set(s["ront_mm"]) == {"LSCI", "MZCI", "MCCI", "MICI"}
    q = s["d_ls_mm"]
    assert set(q) == {"value", "u", "U_k2"} and q["U_k2"] == pytest.approx(2 * q["u"])
    assert "ovality_over_sum_pct" in s and "ovality_over_mean_pct" in s
    # 100.0° < θ < 104.0° in 0.1° float steps: 40 samples
    assert s["gaps"] and s["gaps"][0]["flags"] == {"NO_PEAK": 40}
    assert data["nominal"]["pass"] is False  # ±0.04 mm: the ovality (±0.05 mm) breaks it
    assert data["tool"]["name"] == "lts360" and data["date_utc"].endswith("Z")
    assert data["settings"]["filter"].startswith("ISO 12181-2 Gaussian, 50 UPR")
    assert data["verdict"] == {"pass": False, "failed": ["profile zone"]}
    rows = list(csv.DictReader(open(report_dir / "sections.csv")))
    assert len(rows) == 6 and "U_k2_d_ls_mm" in rows[0] and "ront_mzci_mm" in rows[0]
    assert "scatter_1sigma_mm" in rows[0]
    assert rows[0]["pass"] == "false"  # not Python's False
    for key in ("d_ls_mm", "U_k2_d_max_mm", "ront_mzci_mm", "scatter_1sigma_mm"):
        assert len(rows[0][key].split(".")[1]) == 4, key  # 0.1 µm, no 17-digit floats


def test_a_failed_write_leaves_nothing(tmp_path, monkeypatch):
    from lts360.inspect import report

    ins = inspect_cloud(scan_cloud(n_sections=2))
    monkeypatch.setattr(report, "_fig_polar", lambda ins, k: 1 / 0)  # after the JSON and CSV
    with pytest.raises(ZeroDivisionError):
        write_report(ins, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


_CHECK = """<script>window.addEventListener('load', () => {
  const imgs = [...document.images].map(i => i.naturalWidth + 'x' + i.naturalHeight);
  const pre = document.createElement('pre'); pre.id = 'check';
  pre.textContent = JSON.stringify({imgs, tables: document.querySelectorAll('table').length,
    rows: document.querySelectorAll('tbody tr').length});
  document.body.appendChild(pre);
});</script></body>"""


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("CI") == "true":
            pytest.fail("CI=true but chromium is not installed: the report must be opened in "
                        "a browser there (.ci/run installs it)")
        pytest.skip("chromium is not installed (apt-get install chromium): the page is not "
                    "opened in a browser")
    return exe


_VIEWPORT = """<script>window.addEventListener('load', () => {
  const W = window.innerWidth, H = window.innerHeight;
  const inside = e => { const r = e.getBoundingClientRect();
    return r.left >= 0 && r.right <= W + 0.5 && r.width > 0; };
  const scan = [...document.querySelectorAll('#scan td')];
  const v = document.getElementById('verdict');
  const vr = v.getBoundingClientRect();
  const wide = [...document.body.querySelectorAll('*')].filter(e =>
    !e.closest('div.wide') && e.tagName !== 'SCRIPT' && e.getBoundingClientRect().right > W + 0.5)
    .map(e => e.tagName + (e.id ? '#' + e.id : ''));
  const pre = document.createElement('pre'); pre.id = 'check';
  pre.textContent = JSON.stringify({W, H, scan_cells: scan.length,
    scan_inside: scan.filter(inside).length, verdict: v.textContent,
    verdict_inside: inside(v) && vr.top >= 0 && vr.bottom <= H, wide,
    scroll_width: document.documentElement.scrollWidth});
  document.body.appendChild(pre);
});</script></body>"""


def test_at_1024_px_the_verdict_and_the_scan_table_are_inside_the_viewport(report_dir,
                                                                         tmp_path):
    """In a real headless browser at 1024 × 768: the FAIL banner is the first thing on screen
    (in the screenshot's top rows, in its colour), every value of the scan table lies inside
    the page's width, no element outside a scrolling table box is wider than the page, and
    long unbroken values (command, truth) wrap."""
    exe = _chromium()
    page = tmp_path / "page.html"
    page.write_text((report_dir / "report.html").read_text().replace("</body>", _VIEWPORT))
    flags = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--window-size=1024,768", "--virtual-time-budget=5000"]
    proc = subprocess.run([*flags, "--dump-dom", page.as_uri()], capture_output=True,
                          text=True, timeout=120)
    dom = proc.stdout
    assert '<pre id="check">' in dom, proc.stderr[-2000:]
    check = json.loads(dom.split('<pre id="check">')[1].split("</pre>")[0]
                       .replace("&quot;", '"'))
    assert check["W"] == 1024
    assert check["verdict"].startswith("FAIL") and check["verdict_inside"]
    assert check["scan_cells"] >= 10 and check["scan_inside"] == check["scan_cells"]
    assert check["wide"] == [] and check["scroll_width"] <= 1024
    shot = tmp_path / "shot.png"
    proc = subprocess.run([*flags, f"--screenshot={shot}", (report_dir / "report.html").as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert shot.is_file(), proc.stderr[-2000:]
    from matplotlib.image import imread

    img = imread(shot)[..., :3]
    assert img.shape[1] == 1024
    red = np.all(np.abs(img[:120] - np.array([0xb3, 0x14, 0x1b]) / 255) < 0.04, axis=-1)
    assert red.sum() > 20000  # the banner: ~1000 × 45 px of the FAIL colour at the top


def test_the_page_renders_in_a_headless_browser(report_dir, tmp_path):
    exe = _chromium()
    page = tmp_path / "page.html"
    page.write_text((report_dir / "report.html").read_text().replace("</body>", _CHECK))
    proc = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu",
                           "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                          capture_output=True, text=True, timeout=120)
    dom = proc.stdout
    assert '<pre id="check">' in dom, proc.stderr[-2000:]
    check = json.loads(dom.split('<pre id="check">')[1].split("</pre>")[0]
                       .replace("&quot;", '"'))
    assert len(check["imgs"]) == len(FIGURES)
    assert all(int(w) > 100 and int(h) > 100 for w, h in (s.split("x") for s in check["imgs"]))
    assert check["tables"] >= 3 and check["rows"] >= 6  # scan, events, sections (6 rows), gaps


def test_a_single_section_report(tmp_path):
    ins = inspect_cloud(scan_cloud(n_sections=1, gap_deg=None))
    out = write_report(ins, tmp_path / "one")
    assert "axis" not in ins.data["scan"]
    assert np.isfinite(ins.data["sections"][0]["ront_mm"]["MZCI"]["value"])
    assert (out / "report.html").stat().st_size > 10_000


def test_a_section_seen_over_an_arc_only_is_reported_with_a_warning():
    from lts360.recon.triangulation.cloud import Cloud

    th = np.radians(np.arange(-60.0, 60.0, 0.1))
    r = 10 + 0.05 * np.cos(2 * th)
    n = th.size
    cloud = Cloud(np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(n)]), th, r,
                  np.zeros(n, np.uint8), np.zeros(n, np.uint8), np.zeros(n, np.int32),
                  np.ones(n, np.float32))
    ins = inspect_cloud(cloud)
    s = ins.data["sections"][0]
    assert s["coverage_deg"] == pytest.approx(120.0, abs=0.6)
    assert s["warnings"] and "240°" in s["warnings"][0]
    assert s["d_min_mm"]["value"] is None  # no direction has both ends measured
    from lts360.inspect.report import _html

    assert "<h2>Warnings</h2>" in _html(ins.data, {})


def test_the_json_is_strict(report_dir):
    text = (report_dir / "inspection.json").read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in inspection.json"))


def test_a_moving_scan_reports_when_each_section_and_event_passed(tmp_path):
    """A cloud with row times (a moving object): each section's median time and spread in the
    JSON and the CSV, and every lump or neck-down with the time it passed the laser."""
    import dataclasses

    from lts360.inspect.report import csv_rows

    cloud = scan_cloud(n_sections=12, dent_mm=0.3, dent_z_mm=0.7, dent_sigma_z_mm=0.8)
    speed = 200.0  # mm/s: z = −speed · t
    t = -cloud.points_mm[:, 2] / speed + 1e-4 * (cloud.view.astype(float) - 1)  # views apart
    moving = dataclasses.replace(cloud, time_s=t)
    data = inspect_cloud(moving).data
    s0 = data["sections"][0]
    assert s0["time_s"] == pytest.approx(-s0["z_mm"] / speed, abs=1.1e-4)
    assert s0["time_span_s"] == pytest.approx(2e-4, rel=1e-6)
    assert data["scan"]["events"], "the dent should be found"
    for e in data["scan"]["events"]:
        assert e["time_s"] == pytest.approx(-e["z_extreme_mm"] / speed, abs=1.1e-4)
    assert "time_s" in csv_rows(data)[0]
    still = inspect_cloud(cloud).data
    assert "time_s" not in still["sections"][0] and "time_range_s" not in still["scan"]
