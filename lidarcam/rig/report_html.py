"""The calibration report as one self-contained ``report.html`` (``lidarcam.rig.report.write_report`` writes it beside
``report.md``): every figure embedded as a base64 PNG, the style inline, no script, and a Content-Security-Policy
that lets the page load nothing from anywhere (no network, no other file).

Order: the warnings first, then the answer (``T_lidar_cam``, which maps camera points into the lidar frame, and its
inverse, with the 1-sigma), the summary figure, the verdict and the capture plan, the boards (a table, then each
board's overlay or face-on view and its residual plot), the skipped poses and the extrinsic as YAML.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib_core.geometry.metrics import sigma_rot_deg, sigma_trans_m
from calib_core.geometry.transforms import invert_T, quaternion_xyzw

CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
"""The page's Content-Security-Policy: images only from the page itself (data: URIs), inline style, nothing else."""

STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0 auto; max-width: 1180px;
       padding: 1em 1.5em 3em; color: #1b1b1b; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em;
       margin-top: 1.6em; } h3 { margin-bottom: 0.3em; }
.sub { color: #555; margin-top: 0; }
.warn { background: #fff4e5; border-left: 6px solid #e67e00; padding: 0.6em 1em; margin: 1em 0; }
.warn.alert { background: #fdecea; border-left-color: #c62828; }
.warn li { margin: 0.25em 0; } .warn.alert li:first-child { font-weight: bold; }
.ok { background: #edf7ed; border-left: 6px solid #2e7d32; padding: 0.6em 1em; margin: 1em 0; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.92em; }
th, td { border: 1px solid #d0d0d0; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.n { text-align: right; font-variant-numeric: tabular-nums; }
table.m td { font-family: ui-monospace, Menlo, Consolas, monospace; text-align: right; border: none;
       padding: 0.1em 0.7em; } table.m { border-left: 2px solid #444; border-right: 2px solid #444; }
.answer { display: flex; flex-wrap: wrap; gap: 0 3em; } .answer > div { flex: 1 1 440px; }
.big { font-size: 1.15em; } .big.bad { color: #c62828; }
code, pre { font-family: ui-monospace, Menlo, Consolas, monospace; }
pre { background: #f6f8fa; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
img { max-width: 100%; height: auto; display: block; }
.cards { display: grid; grid-template-columns: repeat(auto-fill, minmax(520px, 1fr)); gap: 1.2em; }
.card { border: 1px solid #d0d0d0; border-radius: 6px; padding: 0.6em; background: #fff; }
.card.rejected { border: 2px solid #c62828; } .card h3 { font-size: 1em; margin: 0 0 0.4em; }
.card .why { color: #c62828; font-size: 0.9em; }
"""


@dataclass
class BoardCard:
    """One board of the report: its row of the table and its figures (PNG files, with their captions)."""

    index: int
    name: str
    points: int
    rms_mm: float
    mean_mm: float
    reproj_px: float | None
    rejected: str | None
    images: list[tuple[Path, str]] = field(default_factory=list)


@dataclass
class HtmlReport:
    """What ``report.html`` shows; ``write_html`` renders it."""

    title: str
    intro: list[str]
    warnings: list[str]
    alerts: int = 0
    """How many of the first ``warnings`` say the result is not to be used (drawn in red)."""
    failure: str | None = None
    headline: str | None = None
    """The answer at a glance, under the title."""
    result: dict = field(default_factory=dict)
    T_lidar_cam: np.ndarray | None = None
    truth: str | None = None
    summary_png: Path | None = None
    fit: str | None = None
    capture: str | None = None
    cards: list[BoardCard] = field(default_factory=list)
    totals: list[str] = field(default_factory=list)
    skipped: dict = field(default_factory=dict)
    yaml: str | None = None


def _e(text) -> str:
    return html.escape(str(text), quote=True)


EMBED_PALETTE_BYTES = 200_000
"""A PNG larger than this (an overlay: a whole camera image) is embedded as a 256-colour palette PNG."""


def _png_bytes(path: Path) -> bytes:
    raw = Path(path).read_bytes()
    if len(raw) <= EMBED_PALETTE_BYTES:
        return raw
    from PIL import Image

    with Image.open(io.BytesIO(raw)) as im:
        small = im.convert("RGB").quantize(256, method=Image.Quantize.MEDIANCUT)
    buf = io.BytesIO()
    small.save(buf, format="PNG", optimize=True)
    return buf.getvalue() if buf.tell() < len(raw) else raw


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(_png_bytes(path)).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{_e(alt)}" title="{_e(alt)}">'


def _num(v, spec: str) -> str:
    return "-" if v is None or not math.isfinite(float(v)) else format(float(v), spec)


def _matrix(M: np.ndarray) -> str:
    rows = "".join("<tr>" + "".join(f"<td>{v + 0.0: .6f}</td>" for v in np.round(r, 6)) + "</tr>" for r in M)
    return f'<table class="m">{rows}</table>'


def _transform_block(name: str, M: np.ndarray, what: str) -> str:
    q = quaternion_xyzw(M[:3, :3])
    angle = math.degrees(math.acos(float(np.clip((np.trace(M[:3, :3]) - 1) / 2, -1, 1))))
    t_mm = 1000 * M[:3, 3]
    return (f"<div><h3><code>{name}</code></h3><p>maps {_e(what)}</p>{_matrix(M)}<ul>"
            f"<li>translation: [{', '.join(f'{v:.1f}' for v in t_mm)}] mm (|t| = {np.linalg.norm(t_mm):.1f} mm)</li>"
            f"<li>rotation angle: {angle:.3f} deg</li>"
            f"<li>quaternion (x, y, z, w): [{', '.join(f'{v:.6f}' for v in q)}]</li></ul></div>")


def _sigma_block(res: dict) -> str:
    cov = res.get("covariance")
    if cov is None:
        return "<p>No covariance in the result: no 1-sigma figures.</p>"
    cov = np.asarray(cov, float)
    sr = np.degrees(np.sqrt(np.diag(cov)[:3]))
    st = 1000 * np.sqrt(np.diag(cov)[3:])
    return (f'<p class="big"><b>1-sigma: rotation {sigma_rot_deg(cov):.3f} deg, translation '
            f"{1000 * sigma_trans_m(cov):.1f} mm</b></p><table><tr><th></th><th>x</th><th>y</th><th>z</th></tr>"
            "<tr><th>rotation (deg, about the lidar axes)</th>" + "".join(f'<td class="n">{v:.3f}</td>' for v in sr)
            + "</tr><tr><th>translation of T_lidar_cam (mm)</th>"
            + "".join(f'<td class="n">{v:.1f}</td>' for v in st) + "</tr></table>"
            f"<p>Covariance model: {_e(res.get('covariance_model') or 'not stated')}.</p>")


def _mounting_block(res: dict) -> str:
    if not res.get("mounting"):
        return ""
    sig, fixed = res.get("mounting_sigma") or {}, res.get("fixed") or {}
    rows = "".join(f'<tr><td>{_e(k)}</td><td class="n">{v:.4f}</td><td class="n">'
                   + ("given (fixed)" if k in fixed else _num(sig.get(k), ".4f")) + "</td></tr>"
                   for k, v in res["mounting"].items())
    return ("<h3>Mounting parameters</h3><p>The camera's pose in the lidar frame (x, y, z the camera centre in "
            "metres; roll, pitch, yaw of its body frame in degrees, Z-Y-X). " + _e(res.get("note") or "") + "</p>"
            f"<table><tr><th>parameter</th><th>value</th><th>1-sigma</th></tr>{rows}</table>")


def _answer(r: HtmlReport) -> str:
    if r.T_lidar_cam is None:
        return f'<h2>Answer</h2><div class="warn alert"><b>The calibration failed</b>: {_e(r.failure)}</div>'
    T = r.T_lidar_cam
    frames = ("<p><code>T_a_b</code> maps points of frame b into frame a. Lidar frame: the scan plane is z = 0, "
              "x forward. Camera frame: z the optical axis, x right, y down. Lengths in metres in the matrices.</p>")
    return ("<h2>Answer</h2>" + frames + '<div class="answer">'
            + _transform_block("T_lidar_cam", T, "camera points into the lidar frame (p_L = R p_C + t)")
            + _transform_block("T_cam_lidar", invert_T(T), "lidar points into the camera frame (the overlays)")
            + "</div>" + _sigma_block(r.result) + _mounting_block(r.result)
            + (f"<p>{_e(r.truth)}</p>" if r.truth else ""))


def _warnings(r: HtmlReport) -> str:
    if not r.warnings:
        return '<div class="ok">No warnings.</div>'
    alert, rest = r.warnings[:r.alerts], r.warnings[r.alerts:]
    out = ""
    if alert:
        out += '<div class="warn alert"><ul>' + "".join(f"<li>{_e(w)}</li>" for w in alert) + "</ul></div>"
    if rest:
        out += (f'<div class="warn"><b>Warnings ({len(rest)})</b><ul>' + "".join(f"<li>{_e(w)}</li>" for w in rest)
                + "</ul></div>")
    return out


def _verdict(r: HtmlReport) -> str:
    v = r.result.get("verdict")
    out = "<h2>Verdict and plan</h2><ul>"
    if isinstance(v, dict) and v.get("consistent") is not None:
        out += ("<li>The method's own test of the answer against the data: "
                + ("consistent." if v["consistent"] else f"<b>contradicted</b>: {_e(v.get('reason'))}") + "</li>")
    if r.fit:
        out += f"<li>{_e(r.fit)}</li>"
    if r.capture:
        out += f"<li>Capture plan: {_e(r.capture)}</li>"
    return out + "</ul>"


def _boards(r: HtmlReport) -> str:
    if not r.cards:
        return ""
    head = ("<tr><th>board</th><th>pose</th><th>points</th><th>residual RMS (mm)</th><th>mean (mm)</th>"
            "<th>corner reproj. RMS (px)</th><th>status</th></tr>")
    rows = "".join(f'<tr><td class="n">{c.index}</td><td><code>{_e(c.name)}</code></td><td class="n">{c.points}</td>'
                   f'<td class="n">{_num(c.rms_mm, ".1f")}</td><td class="n">{_num(c.mean_mm, "+.1f")}</td>'
                   f'<td class="n">{_num(c.reproj_px, ".3f")}</td><td>'
                   + ("used" if c.rejected is None else f"rejected: {_e(c.rejected)}") + "</td></tr>"
                   for c in r.cards)
    cards = "".join(
        f'<div class="card{" rejected" if c.rejected else ""}"><h3>Board {c.index}, pose <code>{_e(c.name)}</code>: '
        f"{c.points} points, RMS {_num(c.rms_mm, '.1f')} mm</h3>"
        + (f'<p class="why">Left out by the calibration: {_e(c.rejected)}</p>' if c.rejected else "")
        + "".join(_img(p, alt) for p, alt in c.images) + "</div>" for c in r.cards)
    return ("<h2>Boards</h2><p>Residual: signed distance of each board's scan points to its plane (the camera's "
            "pose of the board), through the extrinsic.</p>" + f"<table>{head}{rows}</table>"
            + "".join(f"<p>{_e(t)}</p>" for t in r.totals) + f'<div class="cards">{cards}</div>')


def render(r: HtmlReport) -> str:
    """The page's text."""
    glance = r.headline or (f"The calibration failed: {r.failure}" if r.failure else "")
    bad = " bad" if r.alerts or r.failure or "does not fit" in glance else ""
    parts = [f"<h1>{_e(r.title)}</h1>", *(f'<p class="sub">{_e(t)}</p>' for t in r.intro),
             f'<p class="big{bad}"><b>{_e(glance)}</b></p>' if glance else "",
             "<h2>Warnings</h2>",
             _warnings(r), _answer(r)]
    if r.summary_png is not None:
        parts += ["<h2>Summary</h2>", _img(r.summary_png, "summary: the boards from above and their residuals")]
    if r.T_lidar_cam is not None:
        parts.append(_verdict(r))
    parts.append(_boards(r))
    if r.skipped:
        parts += ["<h2>Skipped poses</h2><ul>"] + [f"<li><code>{_e(k)}</code>: {_e(v)}</li>"
                                                  for k, v in r.skipped.items()] + ["</ul>"]
    if r.yaml:
        parts += ["<h2>Extrinsic as YAML</h2>", f"<pre>{_e(r.yaml)}</pre>"]
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f'<meta http-equiv="Content-Security-Policy" content="{CSP}">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{_e(r.title)}</title><style>{STYLE}</style></head><body>\n" + "\n".join(parts)
            + "\n</body></html>\n")


def write_html(path: Path, r: HtmlReport) -> Path:
    """Write ``report.html`` at ``path``."""
    Path(path).write_text(render(r), encoding="utf-8")
    return Path(path)
