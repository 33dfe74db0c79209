"""A capture plan from the boards captured so far: the noise they show, the planner's rig they imply, and the
plan (``capture.plan_capture``). One home for what ``lidarcam plan --from``, ``lidarcam extract``/``bag`` and the
rig report assume: each calls ``plan_from_observations`` with the calibration's extrinsic, covariance and noise.

The calibration's own uncertainty: the plan starts from the covariance the calibration reports (the boards'
dispersion widening included, and any term the model adds to it) and adds each proposed board's information under
the same noise model, that is the model's noise stds times ``widening`` = sqrt of the mean eigenvalue of
``S_model C_cal`` (``S_model``: the planner's information of the captured boards at those stds; 1 when the
calibration's covariance is the model's). So the plan's current 1-sigma is the calibration's, and a proposed board
counts for what a captured one did."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.lines import range_sigma
from ..data.observations import Observations
from .capture import DEFAULT_TARGET, Plan, plan_capture, set_informations
from .views import PlanRig, rig_from_observations

DEFAULT_CORNER_SIGMA_PX = 0.5
"""Corner noise (pixels, 1 sigma per coordinate) assumed when neither the calibration, the extraction's
reprojection RMS nor a rig description gives one."""


@dataclass(frozen=True)
class ObservedPlan:
    """A plan from captured boards: ``rig`` (the planner's rig), ``plan``, and the noise assumed,
    ``range_sigma_m`` (metres) and ``corner_sigma_px`` (pixels; 0 without corners) with where each came from, and
    ``widening``: the factor on both that makes the model's information of the captured boards the calibration's
    covariance (module docstring; the rig's noise stds hold it)."""

    rig: PlanRig
    plan: Plan
    range_sigma_m: float
    corner_sigma_px: float
    noise_source: str
    widening: float = 1.0


def observation_noise(obs: Observations, info: dict | None = None, base: PlanRig | None = None
                      ) -> tuple[float, float, str]:
    """(range sigma (m), corner sigma (px), where they came from) of captured boards: the calibration's estimates
    (``info``: a result's ``range_sigma_m``, ``corner_sigma_px``) first, else the scan lines' spread and the
    extraction's median reprojection RMS (``meta["reproj_rms_px"]``), else ``base``'s corner noise, else
    ``DEFAULT_CORNER_SIGMA_PX``; the corner noise is 0 for boards without corners."""
    info = info or {}
    sr, src_r = (float(info["range_sigma_m"]), "calibration") if info.get("range_sigma_m") else \
        (range_sigma(obs), "scan lines")
    if not obs.has_corners:
        return sr, 0.0, f"range from the {src_r}, no corners"
    rp = [v for v in (obs.meta or {}).get("reproj_rms_px") or [] if v is not None]
    if info.get("corner_sigma_px"):
        sc, src_c = float(info["corner_sigma_px"]), "calibration"
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


def plan_from_observations(obs: Observations, T_lidar_cam: np.ndarray, k: int, *, covariance=None,
                           info: dict | None = None, base: PlanRig | None = None,
                           target: tuple[float, float] = DEFAULT_TARGET, criterion: str = "D") -> ObservedPlan:
    """The next ``k`` board poses after the boards ``obs`` calibrated at ``T_lidar_cam`` with ``covariance`` (6x6,
    the calibration's; None: the model's at the noise found) and ``info`` (the calibration's, whose noise estimates
    it uses: ``observation_noise``), in the rig ``base`` if given (else the one the boards imply:
    ``views.rig_from_observations``). The plan's current prediction is the calibration's covariance; proposed boards
    add information at the noise stds times the widening (module docstring). ValueError without camera intrinsics
    or a usable board."""
    sr, sc, source = observation_noise(obs, info, base)
    T = np.asarray(T_lidar_cam, float)
    infos = set_informations(obs, T, sr, sc)
    S_model = np.sum(infos, axis=0)
    widening = calibration_widening(S_model, covariance)
    current = infos
    if widening != 1.0:
        try:
            current = np.linalg.inv(np.asarray(covariance, float))[None]
        except np.linalg.LinAlgError:
            widening = 1.0
    if round(widening, 2) != 1.0:
        source += f", times {widening:.2f} to the calibration's covariance"
    rig = rig_from_observations(obs, T, sr * widening, sc * widening, base)
    plan = plan_capture(rig, k, current=obs, current_info=current, target=target, criterion=criterion)
    return ObservedPlan(rig, plan, sr * widening, sc * widening, source, widening)
