"""A capture plan from the boards captured so far: the noise they show, the planner's rig they imply, and the
plan (``capture.plan_capture``). One home for what ``lidarcam plan --from``, ``lidarcam extract``/``bag`` and the
rig report assume."""

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
    ``range_sigma_m`` (metres) and ``corner_sigma_px`` (pixels; 0 without corners) with where each came from."""

    rig: PlanRig
    plan: Plan
    range_sigma_m: float
    corner_sigma_px: float
    noise_source: str


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


def plan_from_observations(obs: Observations, T_lidar_cam: np.ndarray, k: int, *, info: dict | None = None,
                           base: PlanRig | None = None, target: tuple[float, float] = DEFAULT_TARGET,
                           criterion: str = "D") -> ObservedPlan:
    """The next ``k`` board poses after the boards ``obs`` at the extrinsic ``T_lidar_cam`` (e.g. their
    calibration, whose ``info`` gives the noise: ``observation_noise``), in the rig ``base`` if given (else the one
    the boards imply: ``views.rig_from_observations``). ValueError without camera intrinsics or a usable board."""
    sr, sc, source = observation_noise(obs, info, base)
    T = np.asarray(T_lidar_cam, float)
    rig = rig_from_observations(obs, T, sr, sc, base)
    plan = plan_capture(rig, k, current=obs, current_info=set_informations(obs, rig.T_lidar_cam, sr, sc),
                        target=target, criterion=criterion)
    return ObservedPlan(rig, plan, sr, sc, source)
