"""Evaluation without ground truth: leave-one-pose-out cross-validation of a calibration method.

For each pose i the method calibrates on the other N-1 poses; pose i's scan points are then measured against
its board plane as the camera sees it, through that extrinsic. Units: the distances in millimetres at the edge
(metres inside), and in units of the range noise: each point-to-plane distance ``e`` divided by its own noise
std ``sigma |m . b|`` (``m`` the plane normal, ``b`` the beam, both in the lidar frame), i.e. the range residual
over ``sigma``. A perfect extrinsic gives 1 in those units; held-out residuals also carry the extrinsic's own
error, so a good calibration lands a little above 1 and a wrong one far above.

Where the method reports a covariance, the held-out residuals are also scored in units of their predicted spread
(``held_out.held_out_spread``: range noise, the fold's extrinsic covariance and the board pose's from its corners);
where the boards carry image corners, the joint held-out residual (``held_out.held_out_joint``: the held-out
board's pose re-estimated from its corners and its scan given the fold's extrinsic), in units of the data's noise
(range: ``range_sigma_m``; corners: ``refine.camera_side.corner_noise_px``, from the boards' own pose fits).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..data.lines import range_sigma
from ..data.observations import Observations
from ..entry import calibrate
from ..errors import JointError, UncertaintyError
from ..model.residuals import plane_residuals
from ..refine.camera_side import corner_noise_px
from ..solvers._common import MIN_BOARDS
from .held_out import HeldOutSpread, held_out_joint, held_out_spread, spread_summary


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """Leave-one-pose-out figures of one method on one set of poses.

    Attributes:
        method: the method's name; options: the options it was called with.
        names: (N,) pose names (``obs.meta["poses"]`` where given, else the board index).
        ok: (N,) whether the fold's calibration succeeded; reasons: (N,) its failure reason or None.
        rms_mm: (N,) RMS point-to-plane distance of the held-out pose's points (mm; NaN where the fold failed).
        rms_sigmas: (N,) RMS of those distances in units of their range noise (module docstring).
        mean_mm: (N,) mean signed distance (mm): a bias of the extrinsic along that board's normal.
        n_points: (N,) points per pose.
        range_sigma_m: the range noise std used as the unit (given, or estimated from the scan lines).
        seconds: wall time of all folds.
        T_lidar_cam: (N,4,4) each fold's extrinsic (NaN where the fold failed): their spread is the leave-one-out
            (jackknife) estimate of the answer's uncertainty.
        spread: the held-out residuals in units of their predicted spread, pooled (None where the method reports no
            covariance); spread_scan_noise: the same with the range noise ``range_sigma_m`` (the scatter about the
            scan lines) in place of the fold's own estimate.
        joint_rms_sigmas: (N,) RMS of the joint held-out residuals (corners and ranges, each over its noise std;
            NaN without corners or where the fold failed); joint_scan_rms_mm: (N,) their range part (mm);
            corner_sigma_px: the corner noise unit (None without corners); joint_n_rows: (N,) residuals per pose in
            the joint score (2 per corner plus the scan points).
    """

    method: str
    names: list[str]
    ok: np.ndarray
    reasons: list[str | None]
    rms_mm: np.ndarray
    rms_sigmas: np.ndarray
    mean_mm: np.ndarray
    n_points: np.ndarray
    range_sigma_m: float
    seconds: float
    options: dict = field(default_factory=dict)
    T_lidar_cam: np.ndarray | None = None
    spread: HeldOutSpread | None = None
    spread_scan_noise: HeldOutSpread | None = None
    joint_rms_sigmas: np.ndarray | None = None
    joint_scan_rms_mm: np.ndarray | None = None
    corner_sigma_px: float | None = None
    joint_n_rows: np.ndarray | None = None

    @property
    def n_ok(self) -> int:
        return int(self.ok.sum())

    @property
    def overall_rms_mm(self) -> float:
        """RMS point-to-plane distance over every held-out point of the successful folds (mm); NaN if none."""
        return _pooled(self.rms_mm, self.n_points, self.ok)

    @property
    def overall_rms_sigmas(self) -> float:
        """The same in units of the range noise (1 = the noise; NaN if no fold succeeded)."""
        return _pooled(self.rms_sigmas, self.n_points, self.ok)

    @property
    def overall_joint_rms_sigmas(self) -> float:
        """RMS of every joint held-out residual (corners and ranges in units of their noise; NaN without)."""
        if self.joint_rms_sigmas is None:
            return float("nan")
        ok = self.ok & np.isfinite(self.joint_rms_sigmas)
        return _pooled(self.joint_rms_sigmas, self.joint_n_rows, ok)

    @property
    def overall_joint_scan_rms_mm(self) -> float:
        """RMS of the joint held-out range residuals (mm; NaN without corners)."""
        if self.joint_scan_rms_mm is None:
            return float("nan")
        return _pooled(self.joint_scan_rms_mm, self.n_points, self.ok & np.isfinite(self.joint_scan_rms_mm))

    def to_dict(self) -> dict:
        """JSON-able form: overall figures, then one row per pose."""
        def num(v):
            return None if not np.isfinite(v) else float(v)

        return {"method": self.method, "n_poses": len(self.names), "n_ok": self.n_ok,
                "overall_rms_mm": num(self.overall_rms_mm), "overall_rms_sigmas": num(self.overall_rms_sigmas),
                "joint_rms_sigmas": num(self.overall_joint_rms_sigmas),
                "joint_scan_rms_mm": num(self.overall_joint_scan_rms_mm),
                "spread": None if self.spread is None else self.spread.to_dict(),
                "spread_scan_noise": None if self.spread_scan_noise is None else self.spread_scan_noise.to_dict(),
                "range_sigma_mm": 1000 * self.range_sigma_m, "seconds": self.seconds,
                "poses": [{"name": n, "ok": bool(o), "reason": r, "rms_mm": num(a), "rms_sigmas": num(b),
                           "mean_mm": num(c), "n_points": int(k)}
                          for n, o, r, a, b, c, k in zip(self.names, self.ok, self.reasons, self.rms_mm,
                                                         self.rms_sigmas, self.mean_mm, self.n_points, strict=True)]}


def _pooled(rms: np.ndarray, n: np.ndarray, ok: np.ndarray) -> float:
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.sum(rms[ok] ** 2 * n[ok]) / np.sum(n[ok])))


def held_out_residuals(obs: Observations, i: int, T_lidar_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Point-to-plane distances (K,) of board ``i``'s scan points to its plane through ``T_lidar_cam`` (metres),
    and the factor (K,) ``|m . b|`` that turns range noise into point-to-plane noise."""
    data = obs.subset([i]).scan_data
    T = np.asarray(T_lidar_cam, float)
    e = plane_residuals(T, data)
    m = data.normals[0] @ T[:3, :3].T
    b = data.points / np.linalg.norm(data.points, axis=1, keepdims=True)
    return e, np.abs(b @ m)


def leave_one_out(obs: Observations, method: str = "lidarcam", *, range_sigma_m: float | None = None,
                  **options) -> CrossValidation:
    """Leave-one-pose-out cross-validation of ``method`` (``calibrate(obs without pose i, method, **options)``
    for each pose i; e.g. ``fixed=...`` for a rig that does not determine every direction).

    ``range_sigma_m``: the range noise std that is the unit of ``rms_sigmas``; default
    ``range_sigma(obs)`` (from the scan lines, no extrinsic). It is not passed to the method; give it
    in ``options`` too if the method should use it. A fold whose calibration fails is recorded with its reason.
    """
    sigma = range_sigma(obs, range_sigma_m)
    N = obs.n_boards
    names = [str(n) for n in (obs.meta or {}).get("poses", [])][:N]
    names += [f"{i:03d}" for i in range(len(names), N)]
    ok = np.zeros(N, bool)
    reasons: list[str | None] = [None] * N
    rms, rms_s, mean = np.full(N, np.nan), np.full(N, np.nan), np.full(N, np.nan)
    joint_s, joint_mm = np.full(N, np.nan), np.full(N, np.nan)
    n_points = np.array([len(b.scan) for b in obs.boards])
    n_rows = n_points + np.array([2 * len(b.corners_px) if b.corners_px is not None else 0 for b in obs.boards])
    sigma_c = corner_noise_px(obs) if obs.has_corners else None
    folds = np.full((N, 4, 4), np.nan)
    parts, parts_lines = [], []
    t0 = time.perf_counter()
    for i in range(N):
        res = calibrate(obs.subset([j for j in range(N) if j != i]), method, **options)
        if not res.ok:
            reasons[i] = res.reason
            continue
        folds[i] = res.T_lidar_cam
        e, f = held_out_residuals(obs, i, res.T_lidar_cam)
        ok[i] = True
        rms[i] = 1000 * np.sqrt(np.mean(e**2))
        rms_s[i] = np.sqrt(np.mean((e / (sigma * np.maximum(f, 1e-6))) ** 2))
        mean[i] = 1000 * np.mean(e)
        if res.covariance is not None:
            info = res.info or {}
            s_c = info.get("corner_sigma_px", sigma_c) if sigma_c is not None else None
            for sr, out in ((info.get("range_sigma_m", sigma), parts), (sigma, parts_lines)):
                out.append(held_out_spread(obs, i, res.T_lidar_cam, res.covariance, sr, s_c))
        if sigma_c is not None:
            joint_s[i], joint_mm[i] = _joint_score(obs, i, res.T_lidar_cam, sigma_c, sigma)
    return CrossValidation(method, names, ok, reasons, rms, rms_s, mean, n_points, sigma,
                           time.perf_counter() - t0, dict(options), folds, spread_summary(parts),
                           spread_summary(parts_lines),
                           joint_s if sigma_c is not None else None, joint_mm if sigma_c is not None else None,
                           sigma_c, n_rows)


def _joint_score(obs: Observations, i: int, T: np.ndarray, sigma_c: float, sigma_r: float) -> tuple[float, float]:
    """(RMS of board ``i``'s joint held-out residuals in noise units, RMS of their range part in mm); NaN where the
    board's pose cannot be re-estimated."""
    try:
        ec, er = held_out_joint(obs, i, T, sigma_c, sigma_r)
    except (JointError, UncertaintyError):
        return float("nan"), float("nan")
    z = np.r_[ec.ravel() / sigma_c, er / sigma_r]
    return float(np.sqrt(np.mean(z**2))), 1000 * float(np.sqrt(np.mean(er**2)))


def jackknife_covariance(T_full: np.ndarray, folds: np.ndarray) -> np.ndarray | None:
    """6x6 jackknife covariance of an extrinsic from its leave-one-out folds (N,4,4; NaN rows skipped): the fold
    answers as left rotation perturbations of ``T_full`` in the lidar frame (rad) and translation offsets (m),
    ``(n-1)/n sum (x_i - mean)(x_i - mean)^T`` (the covariance's convention, ``calib_core.data.result``). None with
    fewer than 3 folds."""
    from ..geometry.transforms import matrix_to_rotvec

    good = folds[np.all(np.isfinite(folds), axis=(1, 2))]
    n = len(good)
    if n < MIN_BOARDS:
        return None
    R0, t0 = T_full[:3, :3], T_full[:3, 3]
    x = np.array([np.concatenate([matrix_to_rotvec(T[:3, :3] @ R0.T), T[:3, 3] - t0]) for T in good])
    d = x - x.mean(axis=0)
    return (n - 1) / n * d.T @ d
