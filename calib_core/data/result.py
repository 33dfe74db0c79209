"""The outcome of one calibration: ``CalibrationResult`` and its JSON form ``lidarcam.result/1``."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..geometry.metrics import pose_errors, sigma_rot_deg, sigma_trans_m
from ..geometry.transforms import invert_T
from .outcome import Outcome

RESULT_SCHEMA = "lidarcam.result/1"

JSON_INFO = ("warnings", "degeneracy", "mounting", "mounting_sigma", "fixed", "note", "alternatives", "prior",
             "intrinsics", "board_dispersion", "covariance_bend", "covariance_modes", "residual_rms", "observations",
             "noise_model", "board_error")
"""Optional ``info`` entries written to the result JSON when present (all JSON-able): the warnings, the
directions a board set does not determine (``calib_core.checks.degeneracy``), and a calibration with fixed parameters
(``calib_core.refine.partial``: all six mounting values, the 1-sigma of the free ones, the fixed ones, a note), the
answers a refused tie could not decide between (``alternatives``: each ``{"T_lidar_cam": 4x4, "cost": the negative
log-likelihood, "mounting": its parameters}``, best first), the mounting prior given (``prior``), how the joint
model treated the camera's intrinsics (``calib_core.model.intrinsics``), and the boards' dispersion test
(``board_dispersion``, ``calib_core.refine.dispersion``: whether the covariance was widened to the boards' spread), and
the likelihood's bend the covariance holds (``covariance_bend``, ``calib_core.refine.bend``), the nearly tied
answers it holds (``covariance_modes``, ``calib_core.refine.modes``), the range
residuals' RMS over the boards used at the method's start and at its answer (``residual_rms``: ``start_m``,
``answer_m``, metres), and which observations the answer was computed from (``observations``:
``observations_fingerprint``). The file's ``noise`` field names each range-noise figure by its source
(``data.outcome.Noise``, metres); ``noise_model`` names the noise model the covariance holds, each scale with
its value and source, and ``board_error`` the per-board systematic error's scale and source
(``data.outcome.NoiseModel``, ``data.outcome.BoardErrorPart``)."""
BEND_REPORTED = 0.5
"""The summary names the covariance's bend (``covariance_bend``) when a re-fit departed from the Gaussian by this
many sigmas or more."""


def observations_fingerprint(obs) -> dict:
    """What identifies the observations a result was computed from: ``{"boards": N, "sha256": hex}``, the hash
    over each board's scan points, camera pose, outline and corners (not the file's bytes nor its ``meta``: a
    re-extraction of the same dataset gives the same fingerprint, another board set another)."""
    h = hashlib.sha256()
    for b in obs.boards:
        for a in (b.scan, b.T_cam_board, b.outline, b.corners_px):
            a = np.zeros(0) if a is None else np.ascontiguousarray(a, float)
            h.update(str(a.shape).encode())
            h.update(a.tobytes())
    return {"boards": int(obs.n_boards), "sha256": h.hexdigest()}


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """One method's answer on one set of observations.

    Attributes:
        method: registry name of the method that produced it.
        ok: True when the method returned a solution; False with ``reason`` otherwise (never a guess).
        T_lidar_cam: 4x4 extrinsic mapping camera points into the lidar frame (metres); None when not ok.
        reason: why the method failed, or None.
        candidates: (M,4,4) every candidate ``T_lidar_cam`` the method considered (M may be 0).
        seconds: wall time of the call.
        covariance: optional 6x6 covariance of the result, tangent-space rotation (rad, left perturbation
            of R in the lidar frame) then translation (m).
        info: method-specific diagnostics (chosen candidate index, costs, conditioning, warnings).
    """

    method: str
    ok: bool
    T_lidar_cam: np.ndarray | None = None
    reason: str | None = None
    candidates: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    seconds: float = 0.0
    covariance: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def T_cam_lidar(self) -> np.ndarray | None:
        """4x4 inverse extrinsic, mapping lidar points into the camera frame; None when not ok."""
        return None if self.T_lidar_cam is None else invert_T(self.T_lidar_cam)

    @property
    def n_candidates(self) -> int:
        """How many candidates the method considered (a loaded result keeps the count, not the matrices)."""
        if not len(self.candidates) and "n_candidates" in self.info:
            return int(self.info["n_candidates"])
        return int(len(self.candidates))

    @property
    def sigma_rot_deg(self) -> float | None:
        """1-sigma rotation uncertainty in degrees (root of the trace of the rotation block), or None."""
        if self.covariance is None:
            return None
        return sigma_rot_deg(self.covariance)

    @property
    def sigma_trans_mm(self) -> float | None:
        """1-sigma translation uncertainty in millimetres (root of the trace of the translation block), or None."""
        if self.covariance is None:
            return None
        return 1000.0 * sigma_trans_m(self.covariance)

    @property
    def outcome(self) -> Outcome:
        """The result's parts as types (``data.outcome``): noise estimates by source, consensus, selection,
        covariance model, verdict, warnings, residual RMS."""
        return Outcome.from_info(self.info)

    @property
    def warnings(self) -> list[str]:
        """Plain-language warnings of the method (``info["warnings"]``; empty when none)."""
        return [str(w) for w in self.info.get("warnings", [])]

    @property
    def boards_used(self) -> list[int] | None:
        """Indices of the boards the answer rests on, for methods that leave boards out (None otherwise)."""
        used = self.info.get("boards_used")
        return None if used is None else [int(i) for i in used]

    @property
    def boards_rejected(self) -> list[dict]:
        """Boards left out by the method: ``{"index", "reason", "statistic"}`` each (empty when none)."""
        return [dict(r) for r in self.info.get("boards_rejected", [])]

    def to_dict(self) -> dict:
        """JSON form under schema ``lidarcam.result/1``; ``warnings`` always, ``boards_used`` and
        ``boards_rejected`` (index, reason, statistic) when the method reports them (optional fields)."""
        d = {"schema": RESULT_SCHEMA, "method": self.method, "ok": bool(self.ok), "reason": self.reason,
             "T_lidar_cam": None if self.T_lidar_cam is None else self.T_lidar_cam.tolist(),
             "T_cam_lidar": None if self.T_cam_lidar is None else self.T_cam_lidar.tolist(),
             "n_candidates": self.n_candidates, "seconds": float(self.seconds)}
        if self.covariance is not None:
            d["covariance"] = np.asarray(self.covariance).tolist()
            d["sigma_rot_deg"] = self.sigma_rot_deg
            d["sigma_trans_mm"] = self.sigma_trans_mm
            if "covariance_model" in self.info:
                d["covariance_model"] = str(self.info["covariance_model"])
        d["warnings"] = self.warnings
        if self.info.get("verdict") is not None:
            d["verdict"] = self.info["verdict"]
        if self.info.get("conditioning") is not None:
            d["conditioning"] = float(self.info["conditioning"])
        if self.boards_used is not None:
            d["boards_used"] = self.boards_used
            d["boards_rejected"] = [{"index": int(r["index"]), "reason": str(r["reason"]),
                                     "statistic": None if r.get("statistic") is None
                                     or not np.isfinite(r["statistic"]) else float(r["statistic"])}
                                    for r in self.boards_rejected]
        for k in JSON_INFO:
            if k not in d and self.info.get(k) is not None:
                d[k] = self.info[k]
        if (noise := self.outcome.noise.to_dict()) is not None:
            d["noise"] = noise
        return d

    def save(self, path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1) + "\n")

    def to_yaml(self, ros=None) -> str:
        """The extrinsic as YAML (``calib_core.data.io.extrinsic_yaml``): method, 1-sigma (deg, mm) and covariance
        model, conditioning, both 4x4 directions (metres), and ``ros`` (a ``FrameExport``) when given; the one
        content of ``lidarcam calibrate --yaml`` and the report's ``extrinsic.yaml``. ValueError when not ok."""
        from .io import extrinsic_yaml

        if not self.ok or self.T_lidar_cam is None:
            raise ValueError(f"{self.method} failed: no extrinsic to write ({self.reason})")
        extra: dict[str, Any] = {"method": self.method}
        if self.covariance is not None:
            extra.update(sigma_rot_deg=self.sigma_rot_deg, sigma_trans_mm=self.sigma_trans_mm)
            if self.info.get("covariance_model"):
                extra["covariance_model"] = f"'{self.info['covariance_model']}'"
        if self.info.get("conditioning") is not None:
            extra["conditioning"] = float(self.info["conditioning"])
        return extrinsic_yaml(self.T_lidar_cam, extra, covariance=self.covariance, ros=ros)

    @classmethod
    def from_dict(cls, d: dict) -> CalibrationResult:
        """The result of a ``lidarcam.result/1`` dict (``to_dict``'s, or ``load_result``'s); candidate matrices are
        not stored, their count is (``n_candidates``)."""
        info = {k: d[k] for k in (*JSON_INFO, "covariance_model", "verdict", "conditioning", "boards_used",
                                  "boards_rejected", "n_candidates", "noise") if d.get(k) is not None}
        T, cov = d.get("T_lidar_cam"), d.get("covariance")
        return cls(method=str(d.get("method", "?")), ok=bool(d.get("ok")), reason=d.get("reason"),
                   T_lidar_cam=None if T is None else np.asarray(T, float), seconds=float(d.get("seconds") or 0.0),
                   covariance=None if cov is None else np.asarray(cov, float), info=info)

    @classmethod
    def load(cls, path) -> CalibrationResult:
        """Read a ``lidarcam.result/1`` file (``save``'s); ObservationError naming the file and field if it is not
        one."""
        return cls.from_dict(load_result(path))

    def summary_lines(self, n_boards: int | None = None, T_true: np.ndarray | None = None) -> list[str]:
        """The result for a reader, one line each: the warnings, ok or the reason, ``T_lidar_cam`` (metres), the
        1-sigma in degrees and millimetres, mounting values, conditioning, boards used and rejected, and the errors
        against ``T_true`` (a known ``T_lidar_cam``) when given. ``n_boards``: the boards the method was given."""
        if not self.ok:
            return [f"{self.method}: failed: {self.reason}"]
        out = [f"warning: {w}" for w in self.warnings  # first: a contradicted answer is read with its warning
               if not (self.boards_rejected and w.startswith("board ") and " left out: " in w)]
        out += [f"{self.method}: ok, {self.n_candidates} candidates, {1000 * self.seconds:.1f} ms",
                "T_lidar_cam (maps camera points into the lidar frame, metres):"]
        out += ["  " + "  ".join(f"{v: .6f}" for v in row) for row in self.T_lidar_cam]
        if self.covariance is not None:
            model = self.info.get("covariance_model")
            out.append(f"1-sigma: rotation {self.sigma_rot_deg:.3f} deg, translation {self.sigma_trans_mm:.1f} mm"
                       + (f" (covariance model: {model})" if model else ""))
            if "intrinsics" in self.info:
                out.append(f"camera intrinsics: {self.info['intrinsics']}")
            if (d := self.info.get("board_dispersion")) is not None:
                verdict = "the covariance is widened to the boards' spread" if d["widened"] else \
                    "beyond the per-beam noise, held by the per-board systematic error estimated from them" \
                    if d.get("held") else "the boards agree with the noise model"
                out.append(f"boards' dispersion: {d['statistic']:.1f} on {d['dof']} degrees of freedom (p "
                           f"{d['p_value']:.1e}): {verdict}")
            if (e := self.info.get("board_error")) is not None and (e["offset_m"] > 0 or e["tilt_m"] > 0):
                out.append(f"per-board systematic error: offset {1000 * e['offset_m']:.1f} mm, tilt "
                           f"{1000 * e['tilt_m']:.1f} mm ({e['source']}"
                           + (f" from {e['dof']} degrees of freedom" if e["source"] == "estimated" else "") + ")")
            if (b := self.info.get("covariance_bend")) is not None and b["departure_sigmas"] >= BEND_REPORTED:
                out.append(f"the likelihood bends along its weakest direction ({b['departure_sigmas']:.1f} sigma off "
                           f"the Gaussian 1.7 sigmas along it): the 1-sigma holds it (Gaussian alone: rotation "
                           f"{b['sigma_rot_deg_laplace']:.3f} deg, translation {b['sigma_trans_mm_laplace']:.1f} mm)")
            if (m := self.info.get("covariance_modes")) is not None:
                out.append(f"the 1-sigma holds the {m['n_modes'] - 1} other answer(s) nearly as likely "
                           f"(likelihood-weighted mixture; the answer's own mode alone: rotation "
                           f"{m['sigma_rot_deg_mode']:.3f} deg, translation {m['sigma_trans_mm_mode']:.1f} mm)")
        if (rms := self.info.get("residual_rms")) is not None:
            start = "" if rms.get("start_m") is None else f"{1000 * rms['start_m']:.1f} mm at the start, "
            out.append(f"range residual RMS (all scan points of the boards used): {start}"
                       f"{1000 * rms['answer_m']:.1f} mm at the answer")
        if "mounting" in self.info:
            out.append("mounting (camera pose in the lidar frame; degrees and metres):")
            held = self.info.get("fixed", {})
            for k, v in self.info["mounting"].items():
                s = self.info["mounting_sigma"].get(k)
                how = "" if k not in held else " (held at the mounting prior's value)" if "prior" in self.info \
                    else " (fixed, given)"
                out.append(f"  {k:>9} = {v: .4f}  " + ("" if s is None else f"+- {s:.4f} (1-sigma)") + how)
        if "conditioning" in self.info:
            out.append("conditioning (inverse condition number, 1 = ideal, < 1e-3 poor): "
                       f"{self.info['conditioning']:.2e}")
        if self.boards_used is not None:
            of = "" if n_boards is None else f" of {n_boards}"
            out.append(f"boards used ({len(self.boards_used)}{of}): " + ", ".join(map(str, self.boards_used)))
            for r in self.boards_rejected:
                stat = "" if r.get("statistic") is None else f" (statistic {r['statistic']:.3g})"
                out.append(f"board {r['index']} rejected{stat}: {r['reason']}")
        if T_true is not None:
            e_R, e_t = pose_errors(self.T_lidar_cam, T_true)
            out.append(f"against ground truth: e_R = {float(e_R):.4f} deg, e_t = {1000 * float(e_t):.1f} mm")
        return out


def load_result(path) -> dict:
    """Read a ``lidarcam.result/1`` JSON file into a dict with numpy 4x4 arrays (None where not ok); every field
    checked (``result_check.check_result_dict``): ObservationError naming the file and the field otherwise."""
    from ..errors import ObservationError
    from .io import read_json
    from .result_check import check_result_dict

    d = read_json(path)
    if not isinstance(d, dict):
        raise ObservationError(f"expected a JSON object at the top, got {type(d).__name__}", file=str(path))
    if d.get("schema") != RESULT_SCHEMA:
        raise ObservationError(f"expected schema {RESULT_SCHEMA!r}", file=str(path), field="schema")
    try:
        d = check_result_dict(d)
    except ObservationError as err:
        raise err.within(file=str(path)) from None
    d.setdefault("warnings", [])            # optional fields: files written before they existed lack them
    d.setdefault("boards_used", None)
    d.setdefault("boards_rejected", [])
    return d
