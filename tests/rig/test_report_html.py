"""``report.html``: one self-contained page (every figure a data: URI, no script, a policy that loads nothing from
anywhere), warnings first, the answer with its frames and 1-sigma, a summary figure, each board's overlay (or,
for observations without images, its face-on view) and residual plot; opened in headless Chromium, every image
loads. Where no browser is installed (``.ci/run`` installs Debian's ``chromium``) the browser test skips."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

import calib_core
from calib_core.data.io import save_observations
from calib_core.data.result import CalibrationResult
from lidarcam.rig.report import write_report
from lidarcam.rig.report_html import CSP
from simulate import SimOptions, generate

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
PROBE = ('<script>addEventListener("load", () => { const im = [...document.images]; const ok = im.filter('
         'i => i.complete && i.naturalWidth > 0).length; document.body.insertAdjacentHTML("beforeend", '
         '`<p id="probe">${ok}/${im.length}</p>`); });</script>')


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """Reports of a dataset with images (overlays) and of observations alone (board views), and a failed one."""
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.extract import extract
    from simulate.dataset import write_dataset

    tmp = tmp_path_factory.mktemp("html")
    opts = SimOptions(n_boards=4, cam_width=400, cam_height=300, focal_px=380.0, noise_mm=5.0, dist_max_m=4.0)
    ds = load_dataset(write_dataset(opts, 7, tmp / "ds"))
    obs, _ = extract(ds)
    assert obs.n_boards == 4
    images = write_report(ds, obs, calib_core.calibrate(obs), tmp / "images")
    only = generate(SimOptions(n_boards=5), seed=2)
    save_observations(only, tmp / "obs.json")
    alone = write_report(None, only, calib_core.calibrate(only), tmp / "alone",
                         alerts=["THE RESULT DOES NOT FIT <these> BOARDS"])
    failed = write_report(None, only, CalibrationResult("lidarcam", False, reason="too few & bad"), tmp / "failed")
    return {"images": (images, 4 + 4 + 1), "alone": (alone, 5 + 5 + 1), "failed": (failed, 0)}


@pytest.mark.parametrize("which", ["images", "alone", "failed"])
def test_the_page_is_self_contained(reports, which):
    summary, n_images = reports[which]
    text = summary.html.read_text()
    srcs = re.findall(r'<img src="([^"]*)"', text)
    assert len(srcs) == n_images and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert f'content="{CSP}"' in text and "<script" not in text and "<link" not in text
    assert not re.search(r"(src|href)=\"(?!data:)", text) and "url(" not in text


def test_the_page_reads_in_order_and_escapes_its_text(reports):
    text = reports["alone"][0].html.read_text()
    order = [text.index(s) for s in ("<h2>Warnings</h2>", "<h2>Answer</h2>", "<h2>Summary</h2>",
                                     "<h2>Verdict and plan</h2>", "<h2>Boards</h2>", "<h2>Extrinsic as YAML</h2>")]
    assert order == sorted(order)
    assert 'class="warn alert"><ul><li>THE RESULT DOES NOT FIT &lt;these&gt; BOARDS</li>' in text
    assert re.search(r"<b>lidarcam: ok; 1-sigma [\d.]+ deg, [\d.]+ mm; 5 of 5 boards used; median board residual", text)
    for needle in ("<code>T_lidar_cam</code>", "maps camera points into the lidar frame", "<code>T_cam_lidar</code>",
                   "1-sigma: rotation", "Capture plan:", "the scans&#x27; own noise", "face-on"):
        assert needle in text, needle
    assert "](summary.png)" in reports["alone"][0].markdown.read_text()
    assert len(reports["alone"][0].board_views) == 5 and not reports["alone"][0].overlays
    assert len(reports["images"][0].overlays) == 4 and not reports["images"][0].board_views
    failed = reports["failed"][0].html.read_text()
    assert "The calibration failed</b>: too few &amp; bad" in failed


def _loaded(browser: str, page, tmp_path, extra: str = "") -> tuple[int, int]:
    """(images loaded, images) of ``page`` as headless Chromium renders it (a copy with a probe script)."""
    text = page.read_text().replace(CSP, CSP + "; script-src 'unsafe-inline'")
    probe = tmp_path / f"probe_{page.parent.name}.html"
    probe.write_text(text.replace("</body>", extra + PROBE + "</body>"))
    run = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
                          "--virtual-time-budget=20000", probe.as_uri()], capture_output=True, text=True, timeout=180)
    m = re.search(r'<p id="probe">(\d+)/(\d+)</p>', run.stdout)
    assert m, (run.returncode, run.stderr[-2000:])
    return int(m.group(1)), int(m.group(2))


def test_chromium_renders_every_image(reports, tmp_path):
    browser = next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)
    if browser is None:
        pytest.skip("no headless browser (chromium) on PATH: .ci/run installs Debian's chromium")
    for which in ("images", "alone"):
        summary, n_images = reports[which]
        assert _loaded(browser, summary.html, tmp_path) == (n_images, n_images), which
    # the probe sees a missing image, and the page's policy refuses a file from outside it
    png = reports["images"][0].overlays[0]
    assert _loaded(browser, reports["alone"][0].html, tmp_path,
                   f'<img src="{png.as_uri()}"><img src="data:image/png;base64,AAAA">') == (11, 13)


def test_residual_bearings_stay_one_run_behind_the_lidar():
    # a board behind the lidar spans +-180 deg: its residual plot's bearings are one run, not two ends of the axis
    import numpy as np

    from lidarcam.rig.report import _bearing_deg

    a = np.radians(np.linspace(170.0, 190.0, 21))
    b = _bearing_deg(np.column_stack([np.cos(a), np.sin(a)]) * 3.0)
    assert np.allclose(np.abs(np.diff(b)), 1.0) and np.ptp(b) == pytest.approx(20.0)
    ahead = _bearing_deg(np.column_stack([np.cos(a - np.pi), np.sin(a - np.pi)]))
    np.testing.assert_allclose(ahead, np.linspace(-10.0, 10.0, 21), atol=1e-9)
