"""A capture plan from the boards captured so far: the noise they show, the planner's rig they imply, and the
plan (``capture.plan_capture``). One home for what ``lidarcam plan --from``, ``lidarcam extract``/``bag`` and the
rig report assume: each calls ``plan_from_observations`` with the calibration's extrinsic, covariance and noise.

The calibration's own uncertainty: the plan predicts with the calibration's noise model (``info["noise_model"]``:
per-beam range noise, corner noise, and the per-board systematic error of ``info["board_error"]``; the file's
stated ``board_range_sigma_m`` or the calibration's prior, ``refine.systematic.DEFAULT_PRIOR``, where the result
names none), so that the model's 1-sigma of the captured boards is the calibration's. Where a covariance is given,
the plan's current prediction is that covariance itself (the captured boards' systematic part is set to
``M0 = H0 C_cal H0 - H0`` so that their sandwich is ``C_cal``; it is the model's own ``M0`` where the model gives
``C_cal``), and proposed boards are added under the same noise model times ``widening`` = sqrt of the mean
eigenvalue of ``S_model C_cal`` (``S_model``: the inverse of the model's covariance of the captured boards; 1 when
the calibration's covariance is the model's), a factor on the noise stds and on the systematic scale alike (so on
the covariance as a whole). So the plan's current 1-sigma is the calibration's, and a proposed board counts for
what a captured one did."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.lines import range_sigma
from ..data.observations import Observations
from ..model.board_error import BoardErrorScale
from ..refine.systematic import DEFAULT_PRIOR
from .capture import DEFAULT_TARGET, Plan, plan_capture, predict, set_informations
from .views import PlanRig, rig_from_observations

DEFAULT_CORNER_SIGMA_PX = 0.5
"""Corner noise (pixels, 1 sigma per coordinate) assumed when neither the calibration, the extraction's
reprojection RMS nor a rig description gives one."""


@dataclass(frozen=True)
class ObservedPlan:
    """A plan from captured boards: ``rig`` (the planner's rig), ``plan``, and the noise assumed,
    ``range_sigma_m`` (metres) and ``corner_sigma_px`` (pixels; 0 without corners) with where each came from, and
    ``widening``: the factor on both that makes the model's information of the captured boards the calibration's
    covariance (module docstring; the rig's noise stds hold it), and ``board_error`` the per-board systematic scale
    (metres; widened too; ``board_error_scale``)."""

    rig: PlanRig
    plan: Plan
    range_sigma_m: float
    corner_sigma_px: float
    noise_source: str
    widening: float = 1.0
    board_error: BoardErrorScale = DEFAULT_PRIOR


def observation_noise(obs: Observations, info: dict | None = None, base: PlanRig | None = None
                      ) -> tuple[float, float, str]:
    """(range sigma (m), corner sigma (px), where they came from) of captured boards: the calibration's noise
    model (``info["noise_model"]``, else a result's ``range_sigma_m``, ``corner_sigma_px``) first, else the scan
    lines' spread and the extraction's median reprojection RMS (``meta["reproj_rms_px"]``), else ``base``'s corner
    noise, else ``DEFAULT_CORNER_SIGMA_PX``; the corner noise is 0 for boards without corners."""
    info = info or {}
    nm = info.get("noise_model") or {}
    sr_cal = nm.get("range_sigma_m") or info.get("range_sigma_m")
    sc_cal = nm.get("corner_sigma_px") or info.get("corner_sigma_px")
    sr, src_r = (float(sr_cal), "calibration") if sr_cal else (range_sigma(obs), "scan lines")
    if not obs.has_corners:
        return sr, 0.0, f"range from the {src_r}, no corners"
    rp = [v for v in (obs.meta or {}).get("reproj_rms_px") or [] if v is not None]
    if sc_cal:
        sc, src_c = float(sc_cal), "calibration"
    elif rp:
        sc, src_c = float(np.median(rp)), "reprojection RMS"
    elif base is not None:
        sc, src_c = float(base.corner_sigma_px), "rig description"
    else:
        sc, src_c = DEFAULT_CORNER_SIGMA_PX, "default"
    return sr, sc, f"range from the {src_r}, corners from the {src_c}"


def calibration_widening(information: np.ndarray, covariance) -> float:
    """sqrt of the mean eigenvalue of ``information @ covariance`` (the model's 6x6 information of the captured
    boards, the calibration's 6x6 covariance): how much larger the calibration's uncertainty is than the model's, as a
    factor on the noise stds; 1 when either is missing, singular or not finite."""
    if covariance is None:
        return 1.0
    C = np.asarray(covariance, float)
    if C.shape != (6, 6) or not np.all(np.isfinite(C)) or not np.all(np.isfinite(information)):
        return 1.0
    ratio = float(np.trace(np.asarray(information, float) @ C)) / 6.0
    return float(np.sqrt(ratio)) if np.isfinite(ratio) and ratio > 0 else 1.0


def board_error_scale(obs: Observations, info: dict | None = None) -> tuple[BoardErrorScale, str]:
    """The per-board systematic scale (metres) the calibration's covariance holds and where it came from: the
    result's ``info["board_error"]`` where its noise model holds the term, none where the result's noise model
    names none (a fold's covariance, another method's), else the file's stated ``board_range_sigma_m``, else the
    calibration's prior (``refine.systematic.DEFAULT_PRIOR``)."""
    info = info or {}
    be = info.get("board_error")
    if be is not None and info.get("noise_model") is not None and "per-board" not in \
            str(info["noise_model"].get("name", "")):
        be = None
        if info["noise_model"].get("name"):
            return BoardErrorScale(), "none (the calibration's noise model holds none)"
    if be is not None:
        return BoardErrorScale(float(be["offset_m"]), float(be["tilt_m"])), str(be.get("source", "calibration"))
    if obs.board_range_sigma_m is not None:
        return BoardErrorScale(float(obs.board_range_sigma_m), 0.0), "stated"
    return DEFAULT_PRIOR, "prior"


def plan_from_observations(obs: Observations, T_lidar_cam: np.ndarray, k: int, *, covariance=None,
                           info: dict | None = None, base: PlanRig | None = None,
                           target: tuple[float, float] = DEFAULT_TARGET, criterion: str = "D") -> ObservedPlan:
    """The next ``k`` board poses after the boards ``obs`` calibrated at ``T_lidar_cam`` with ``covariance`` (6x6,
    the calibration's; None: the model's at the noise found) and ``info`` (the calibration's, whose noise model
    it uses: ``observation_noise``, ``board_error_scale``), in the rig ``base`` if given (else the one the boards
    imply: ``views.rig_from_observations``); of the boards the calibration used (``info["boards_used"]``) where it
    names them. The plan's current prediction is the calibration's covariance;
    proposed boards add information under the same noise model times the widening (module docstring). ValueError
    without camera intrinsics or a usable board."""
    used = (info or {}).get("boards_used")
    if used is not None and 0 < len(used) < obs.n_boards:      # the boards the calibration's answer rests on
        obs = obs.subset([int(i) for i in used])
    sr, sc, source = observation_noise(obs, info, base)
    scale, scale_src = board_error_scale(obs, info)
    if scale.active:
        source += (f", per-board systematic error {1000 * scale.offset_m:.1f} mm offset, "
                   f"{1000 * scale.tilt_m:.1f} mm tilt ({scale_src})")
    T = np.asarray(T_lidar_cam, float)
    infos = set_informations(obs, T, sr, sc, board_error=scale)
    model = predict(np.sum(infos, axis=0)).covariance
    widening = calibration_widening(np.linalg.inv(model), covariance) if model is not None else 1.0
    current = infos
    if covariance is not None and widening != 1.0:
        H0 = np.sum(infos[:, 0], axis=0) / widening**2        # the captured boards' per-beam information, widened
        C = np.asarray(covariance, float)
        current = np.stack([H0, H0 @ C @ H0 - H0])[None]       # sandwich(H0, M0) is the calibration's covariance
    if abs(widening - 1.0) >= 0.05:
        source += f", times {widening:.2f} to the calibration's covariance"
    wide = BoardErrorScale(scale.offset_m * widening, scale.tilt_m * widening)
    rig = rig_from_observations(obs, T, sr * widening, sc * widening, base, wide)
    plan = plan_capture(rig, k, current=obs, current_info=current, target=target, criterion=criterion)
    return ObservedPlan(rig, plan, sr * widening, sc * widening, source, widening, wide)
