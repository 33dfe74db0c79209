"""Capture planning: what a board set will give before (or while) it is captured, and which board poses to take
next, from the Fisher information of the joint model over corners and ranges (``joint.board_informations``).

Parameters and units of a prediction: the extrinsic's ``(w, dt)`` of ``calib_core.model.residuals``: ``w`` a small
rotation applied on the lidar side, ``R_lidar_cam <- exp([w]x) R_lidar_cam`` (so roll, pitch, yaw are rotations
about the lidar's x, y, z axes), ``dt`` the change of ``t_lidar_cam`` (x, y, z along the lidar's axes). The
1-sigma of each is shown in degrees and millimetres. The information of a set of boards is the sum of its boards'
(each board's own pose marginalised), so a plan is a sum of 6x6 matrices: the greedy search adds, one board at a
time, the feasible pose that most improves the criterion (D-optimal: the largest log-determinant; or the smallest
variance of one axis, or of the rotation or translation as a whole).

The per-board systematic error (``calib_core.model.board_error``, the rig's ``board_error``) is in every
prediction as the calibration holds it (``refine.systematic.with_systematic``): the answer is weighed by the
per-beam noise, so a set's covariance is the sandwich ``H^-1 + H^-1 M H^-1`` of ``H``, the sum of the boards'
per-beam information, and ``M``, the sum of each board's systematic part (``set_systematic``). A plan's
"information" is therefore the pair ``(H, M)`` stacked as (..., 2, 6, 6) (a plain (..., 6, 6) is ``H`` with
``M = 0``): still a sum over boards. Each board adds at most the information its systematic error leaves, so
where that error dominates, a target may take more boards than the planner's limit (``limited_by_systematic``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..checks.degeneracy import AXES, undetermined_directions
from ..data.observations import MAX_BOARDS, Observations
from ..errors import LidarcamError
from ..model.board_error import BoardErrorScale
from .information import (
    SIGMA_NAMES,
    Prediction,
    as_pair,
    limited_by_systematic,
    predict,
    sandwich,
    set_informations,
    set_systematic,
)
from .views import POSE_FIELDS, REJECTIONS, PlanRig, board_poses_lidar, feasibility, noise_free_views

CRITERIA = ("D", "rot", "trans") + AXES
"""``D``: D-optimal; ``rot`` / ``trans``: the trace of the rotation / translation covariance; an axis name: its
variance."""

PRIOR_SIGMA = (np.radians(30.0), 3.0)
"""A weak prior (1-sigma: rotation rad, translation m) that keeps the greedy criterion finite while the set does
not yet determine every direction; it never enters a reported prediction."""

MAX_PLAN_BOARDS = 200
"""The most boards a plan (current + proposed) is extended to while it looks for the target."""
DEFAULT_TARGET = (0.1, 5.0)
"""The 1-sigma target of a plan: rotation (deg), translation (mm)."""
REPEAT_ANGLE_DEG = 15.0
"""A candidate within the separation of a proposed board whose normal is within this of that board's repeats it:
passed over in every round while another candidate remains (the workspace grid's turn and lean steps are larger)."""


class PlanError(LidarcamError):
    """The planner cannot answer: no feasible board pose in the workspace, or an unknown criterion."""


def pool(rig: PlanRig) -> tuple[np.ndarray, np.ndarray]:
    """The feasible workspace grid: poses (M,6) in ``POSE_FIELDS`` units and their information (M,2,6,6) under
    the rig's noise, per-board systematic error included (``set_informations``). PlanError when no pose is
    feasible."""
    grid = rig.workspace.grid()
    reason, ranges, bearings = feasibility(rig, board_poses_lidar(rig, grid))
    ok = reason < 0
    if not ok.any():
        counts = np.bincount(reason[reason >= 0], minlength=len(REJECTIONS))
        detail = "; ".join(f"{c} {w}" for c, w in zip(counts, REJECTIONS, strict=True) if c)
        raise PlanError(f"no board pose of the workspace grid ({len(grid)} poses) is feasible: {detail}")
    poses, ranges = grid[ok], ranges[ok]
    T = board_poses_lidar(rig, poses)
    infos = []
    for s in range(0, len(poses), MAX_BOARDS):
        views = noise_free_views(rig, T[s:s + MAX_BOARDS], ranges[s:s + MAX_BOARDS], bearings)
        infos.append(set_informations(views, rig.T_lidar_cam, rig.range_sigma_m, rig.corner_sigma_px,
                                      board_error=rig.board_error))
    return poses, np.concatenate(infos)


def _scores(S: np.ndarray, C: np.ndarray, criterion: str) -> np.ndarray:
    """Criterion per candidate for the information ``S + C_m`` (pairs, ``as_pair``; higher is better), a weak
    prior added to ``H``: of the covariance ``sandwich`` (D-optimal: minus its log-determinant)."""
    prior = np.diag(np.r_[np.full(3, PRIOR_SIGMA[0] ** -2), np.full(3, PRIOR_SIGMA[1] ** -2)])
    S, C = as_pair(S), as_pair(C)
    A = S[0][None] + C[:, 0] + prior[None]
    M = S[1][None] + C[:, 1]
    if criterion == "D" and not M.any():
        return np.linalg.slogdet(A)[1]
    cov = sandwich(np.linalg.inv(A), M)
    if criterion == "D":
        return -np.linalg.slogdet(cov)[1]
    if criterion == "rot":
        return -np.trace(cov[:, :3, :3], axis1=1, axis2=2)
    if criterion == "trans":
        return -np.trace(cov[:, 3:, 3:], axis1=1, axis2=2)
    j = AXES.index(criterion)
    return -cov[:, j, j]


def greedy(S0: np.ndarray, candidates: np.ndarray, n: int, criterion: str = "D", centres: np.ndarray | None = None,
           min_separation_m: float = 0.0, normals: np.ndarray | None = None) -> list[int]:
    """Indices of ``n`` candidates (each at most once) chosen one at a time to maximise ``criterion`` of
    ``S0 + sum of the chosen candidates' information`` (``candidates`` (M,6,6) or pairs (M,2,6,6), ``as_pair``).
    With ``centres`` (M,3, metres), a
    candidate closer than ``min_separation_m`` to a board chosen in the current round is passed over, so that the
    proposed boards stand at distinct places; a round ends when every place is taken (boards may then share one).
    With ``normals`` (M,3, unit) too, a candidate that repeats a chosen board (``REPEAT_ANGLE_DEG``) stays passed
    over after a round ends, while any other remains: a compact workspace gets distinct poses, not near-repeats."""
    if criterion not in CRITERIA:
        raise PlanError(f"unknown criterion {criterion!r}; one of {', '.join(CRITERIA)}")
    candidates = as_pair(candidates)
    S, free, out = as_pair(np.array(S0, float)), np.ones(len(candidates), bool), []
    taken, repeats = np.zeros(len(candidates), bool), np.zeros(len(candidates), bool)
    for _ in range(min(n, len(candidates))):
        if not (free & ~taken).any():
            taken = repeats.copy() if (free & ~repeats).any() else np.zeros(len(candidates), bool)
        sc = np.where(free & ~taken, _scores(S, candidates, criterion), -np.inf)
        k = int(np.argmax(sc))
        out.append(k)
        free[k] = False
        S = S + candidates[k]
        if centres is not None:
            near = np.linalg.norm(centres - centres[k], axis=1) < min_separation_m
            taken |= near
            if normals is not None:
                repeats |= near & (np.abs(normals @ normals[k]) > np.cos(np.radians(REPEAT_ANGLE_DEG)))
    return out


@dataclass(frozen=True, eq=False)
class Plan:
    """A capture plan.

    Attributes:
        current: the prediction of the boards captured so far; current_n: how many.
        undetermined: the axes (``AXES``) the current set leaves undetermined or weak, and the degeneracy
            analysis's sentence (``message``); plan_undetermined, plan_message: the same after the proposed boards.
        poses: (K,6) the proposed poses (``POSE_FIELDS`` units); after: the prediction after each.
        extension: predictions after each further greedy board beyond K (for the sigma-vs-boards curve);
        to_target: boards in all (current + proposed) that reach ``target``, None if not within
            ``MAX_PLAN_BOARDS``. T_lidar_board: (K,4,4) the proposed poses in the lidar frame.
        board_error: the per-board systematic scale the plan holds (the rig's); limited_by_systematic: the target
            is not reached within ``MAX_PLAN_BOARDS`` and that scale is what stops it (``limited_by_systematic``).
    """

    current: Prediction
    current_n: int
    undetermined: tuple[str, ...]
    message: str
    poses: np.ndarray
    after: tuple[Prediction, ...]
    extension: tuple[Prediction, ...]
    to_target: int | None
    target: tuple[float, float]
    criterion: str
    plan_undetermined: tuple[str, ...]
    plan_message: str
    T_lidar_board: np.ndarray
    board_error: BoardErrorScale = BoardErrorScale()
    limited_by_systematic: bool = False

    def summary_lines(self, rig: PlanRig) -> list[str]:
        """The plan for a reader, one line each (as ``lidarcam plan`` prints it): the current prediction (deg,
        mm), the table of proposed poses with the predicted 1-sigma after each, the boards to the target, the
        operator's checklist at ``rig`` and the verdict."""
        return _summary_lines(self, rig)


def name_undetermined(obs: Observations | None, T_lidar_cam: np.ndarray, range_sigma_m: float
                      ) -> tuple[tuple[str, ...], str]:
    """The axes a board set leaves undetermined or weak and the degeneracy analysis's sentence
    (``checks.degeneracy.undetermined_directions`` at the given range noise); all six with no boards."""
    if obs is None or obs.n_boards == 0:
        return AXES, "no boards yet: nothing is determined"
    deg = undetermined_directions(obs, T_lidar_cam, range_sigma_m)
    return (deg.axes if len(deg.directions) else ()), deg.message()


def separation_m(rig: PlanRig) -> float:
    """How far apart (metres, board centres) proposed boards stand: half the board's largest extent."""
    outline = np.asarray(rig.outline, float)
    return 0.5 * float(np.max(np.linalg.norm(outline[:, None] - outline[None], axis=-1)))


def plan_capture(rig: PlanRig, k: int, *, current: Observations | None = None, current_info: np.ndarray | None = None,
                 target: tuple[float, float] = DEFAULT_TARGET, criterion: str = "D") -> Plan:
    """The next ``k`` board poses for ``rig`` after the boards ``current`` (their per-board information
    ``current_info`` (N,6,6) or pairs (N,2,6,6) at the rig's mounting and noise, e.g. from ``set_informations``
    with the rig's ``board_error``), and how many boards
    reach ``target`` = (rotation deg, translation mm) of ``rot_sigma_deg`` and ``trans_sigma_mm``."""
    poses, C = pool(rig)
    S0 = np.zeros((2, 6, 6)) if current_info is None or not len(current_info) else \
        np.sum(as_pair(current_info), axis=0)
    n0 = 0 if current is None else current.n_boards
    more = max(k, MAX_PLAN_BOARDS - n0)
    T_pool = board_poses_lidar(rig, poses)
    centre = np.r_[np.asarray(rig.outline, float).mean(axis=0), 0.0]
    order = greedy(S0, C, more, criterion, T_pool[:, :3, :3] @ centre + T_pool[:, :3, 3], separation_m(rig),
                   T_pool[:, :3, 2])
    cum = S0[None] + np.cumsum(C[order], axis=0)
    preds = [predict(F) for F in cum]
    now = predict(S0)
    reached = [i for i, p in enumerate([now] + preds) if p.meets(target)]
    limited = not reached and limited_by_systematic(cum[-1], target)
    chosen = order[:k]
    T_new = board_poses_lidar(rig, poses[chosen])
    names, msg = name_undetermined(current, rig.T_lidar_cam, rig.range_sigma_m)
    planned = _with(current, rig, T_new)
    p_names, p_msg = name_undetermined(planned, rig.T_lidar_cam, rig.range_sigma_m)
    return Plan(now, n0, names, msg, poses[chosen], tuple(preds[:k]), tuple(preds[k:]),
                n0 + reached[0] if reached else None, tuple(target), criterion, p_names, p_msg, T_new,
                rig.board_error, bool(limited))


def systematic_words(plan: Plan) -> str:
    """The one line on a target the per-board systematic error puts out of reach (``Plan.limited_by_systematic``):
    the scale, and what ``MAX_PLAN_BOARDS`` boards would give."""
    last = plan.extension[-1] if plan.extension else plan.after[-1] if plan.after else plan.current
    be = plan.board_error
    return (f"the target ({plan.target[0]:g} deg, {plan.target[1]:g} mm) is out of reach: limited by the per-board "
            f"systematic error ({1000 * be.offset_m:.1f} mm offset, {1000 * be.tilt_m:.1f} mm tilt per board caps what "
            f"each board adds; {plan.current_n + len(plan.after) + len(plan.extension)} boards "
            f"give {last.rot_sigma_deg:.2f} deg, {last.trans_sigma_mm:.1f} mm)")


def _with(current: Observations | None, rig: PlanRig, T_lidar_board: np.ndarray) -> Observations | None:
    """The current boards (if any) and noise-free views of ``T_lidar_board``, at most ``MAX_BOARDS``."""
    if not len(T_lidar_board):
        return current
    _, ranges, bearings = feasibility(rig, T_lidar_board)
    new = noise_free_views(rig, T_lidar_board, ranges, bearings)
    if current is None:
        return new
    boards = (current.boards + new.boards)[:MAX_BOARDS]
    return Observations(boards, rig.T_lidar_cam, {}, current.camera or rig.camera)


def pose_dict(pose: np.ndarray) -> dict:
    """``{"distance_m": ..., ..., "roll_deg": ...}`` of one planner pose (6,)."""
    return {k: round(float(v), 4) for k, v in zip(POSE_FIELDS, pose, strict=True)}


def _pred_dict(p: Prediction) -> dict:
    finite = {k: (float(v) if np.isfinite(v) else None) for k, v in (("rot_sigma_deg", p.rot_sigma_deg),
                                                                      ("trans_sigma_mm", p.trans_sigma_mm))}
    return {**finite, "sigma": p.sigma_dict()}


def plan_to_dict(plan: Plan) -> dict:
    """JSON-able plan: ``current`` (``rot_sigma_deg``, ``trans_sigma_mm``, ``sigma`` per axis, ``undetermined``)
    and ``next`` (each proposed pose with the predicted sigmas after it); None where a sigma is undetermined."""
    nxt = [{"pose": pose_dict(q), "T_lidar_board": np.round(T, 6).tolist(), "boards": plan.current_n + i + 1,
            **_pred_dict(p)} for i, (q, T, p) in enumerate(zip(plan.poses, plan.T_lidar_board, plan.after,
                                                                 strict=True))]
    return {"schema": "lidarcam.plan/1", "criterion": plan.criterion,
            "target": {"rot_sigma_deg": plan.target[0], "trans_sigma_mm": plan.target[1]},
            "boards_to_target": plan.to_target, "verdict": plan_summary(plan),
            "board_error": {"offset_m": plan.board_error.offset_m, "tilt_m": plan.board_error.tilt_m},
            "limited_by_systematic": plan.limited_by_systematic,
            "current": {**_pred_dict(plan.current), "undetermined": list(plan.undetermined)},
            "current_boards": plan.current_n, "current_message": plan.message,
            "next": nxt, "after_next": {"undetermined": list(plan.plan_undetermined), "message": plan.plan_message}}


AXIS_WORDS = {"roll": "roll", "pitch": "pitch", "yaw": "yaw", "x": "x", "y": "y", "z": "height (z)"}


def describe_pose(pose: np.ndarray) -> str:
    """An operator's words for a planner pose: ``3.0 m at bearing +10 deg, lean +40 deg, turn -40 deg``."""
    d = pose_dict(pose)
    words = [f"{d['distance_m']:.1f} m away at bearing {d['bearing_deg']:+.0f} deg"]
    if d["height_m"]:
        words.append(f"centre {d['height_m']:+.2f} m above the scan plane")
    words.append(f"top leaned {'back' if d['lean_deg'] >= 0 else 'forward'} {abs(d['lean_deg']):.0f} deg")
    words.append(f"turned {abs(d['turn_deg']):.0f} deg {'left' if d['turn_deg'] >= 0 else 'right'}")
    if d["roll_deg"]:
        words.append(f"rolled {d['roll_deg']:+.0f} deg in its plane")
    return ", ".join(words)


def weakest_axis(p: Prediction, target: tuple[float, float]) -> tuple[str, str]:
    """The axis farthest above its share of ``target`` (each axis ``target / sqrt(3)``) and its 1-sigma in words."""
    share = np.r_[np.full(3, np.radians(target[0])), np.full(3, target[1] / 1000.0)] / np.sqrt(3.0)
    j = int(np.argmax(np.where(np.isfinite(p.sigma), p.sigma / share, np.inf)))
    s = p.sigma[j]
    value = "undetermined" if not np.isfinite(s) else f"{np.degrees(s):.2f} deg" if j < 3 else f"{1000 * s:.0f} mm"
    return AXES[j], value


def _fmt(v, unit: str) -> str:
    return "   undet." if v is None or not np.isfinite(v) else f"{v:8.3f}" if unit == "deg" else f"{v:8.1f}"


def _summary_lines(plan: Plan, rig: PlanRig) -> list[str]:
    cur = plan.current
    und = "undetermined"
    out = [f"current: {plan.current_n} boards; range noise {1000 * rig.range_sigma_m:.1f} mm, corner noise "
           f"{rig.corner_sigma_px:.2g} px",
           "  1-sigma: rotation " + (und if not np.isfinite(cur.rot_sigma_deg) else f"{cur.rot_sigma_deg:.3f} deg")
           + ", translation " + (und if not np.isfinite(cur.trans_sigma_mm) else f"{cur.trans_sigma_mm:.1f} mm"),
           "  per axis (rotations about the lidar axes; translation of T_lidar_cam): "
           + ", ".join(f"{k} {'undet.' if v is None else f'{v:.3g}'}" for k, v in cur.sigma_dict().items()),
           f"  {plan.message}", "",
           f"next {len(plan.poses)} boards ({plan.criterion}-optimal), predicted 1-sigma after each:",
           " #  dist_m  bear_deg  height_m  turn_deg  lean_deg  roll_deg |  rot_deg  trans_mm |"
           + "".join(f" {k:>9}" for k in SIGMA_NAMES)]
    for i, (q, p) in enumerate(zip(plan.poses, plan.after, strict=True)):
        sd = p.sigma_dict()
        out.append(f"{i + 1:2d}  {q[0]:6.2f}  {q[1]:8.1f}  {q[2]:8.2f}  {q[3]:8.1f}  {q[4]:8.1f}  {q[5]:8.1f} |"
                   f" {_fmt(p.rot_sigma_deg, 'deg')}  {_fmt(p.trans_sigma_mm, 'mm')} |"
                   + "".join(f" {_fmt(sd[k], 'deg' if k.endswith('deg') else 'mm'):>9}" for k in SIGMA_NAMES))
    if plan.plan_undetermined:
        out.append(f"after these boards: {plan.plan_message}")
    if plan.limited_by_systematic:
        out.append(systematic_words(plan))
    else:
        out.append(f"to reach the target ({plan.target[0]:g} deg, {plan.target[1]:g} mm): "
                   + (f"{plan.to_target} boards in all" if plan.to_target is not None else
                      "not within the planner's limit of boards; lower the noise or widen the workspace"))
    if plan.current_n == 0 and not plan.limited_by_systematic and (plan.to_target is None
                                                                    or plan.to_target > MANY_BOARDS):
        out.append(what_limits(rig, plan))
    _, ranges, _ = feasibility(rig, plan.T_lidar_board)
    out += ["", "checklist at the rig:"]
    out += [f"  [ ] {i + 1}. board {describe_pose(q)}; check: the whole board in the image with "
            f"{rig.image_margin_px:g} px to spare, the scan line across it (about {int(np.isfinite(r).sum())} points)"
            for i, (q, r) in enumerate(zip(plan.poses, ranges, strict=True))]
    return out + ["", f"verdict: {plan_summary(plan)}"]


MANY_BOARDS = 30
"""A plan from a rig description that needs more boards than this says what limits it (``what_limits``)."""


def what_limits(rig: PlanRig, plan: Plan) -> str:
    """One line on what limits a plan from a rig description: the boards in all that reach its target with half the
    range noise and with half the corner noise (the rest of the rig as it is)."""
    def boards(r: PlanRig) -> str:
        n = plan_capture(r, 1, target=plan.target, criterion=plan.criterion).to_target
        return "none within the limit" if n is None else f"{n}"

    parts = [f"half the range noise ({500 * rig.range_sigma_m:.0f} mm): "
             + boards(replace(rig, range_sigma_m=rig.range_sigma_m / 2))]
    if rig.corner_sigma_px > 0:
        parts.append(f"half the corner noise ({rig.corner_sigma_px / 2:.2g} px): "
                     + boards(replace(rig, corner_sigma_px=rig.corner_sigma_px / 2)))
    axis, value = weakest_axis(plan.after[-1] if plan.after else plan.current, plan.target)
    return (f"what limits it: the noise, the weakest axis {AXIS_WORDS[axis]} ({value} after the proposed boards); "
            "boards in all to the target with " + "; with ".join(parts))


def boards_to_add(plan: Plan) -> int | None:
    """How many boards beyond the current ones reach the plan's target (0: met now; None: not within
    ``MAX_PLAN_BOARDS``)."""
    return None if plan.to_target is None else plan.to_target - plan.current_n


def plan_summary(plan: Plan) -> str:
    """One sentence on what the current boards give and what to add: as many boards as reach the target (the
    plan's first poses named), or the proposed poses where the target is out of reach."""
    if plan.undetermined:
        what = ", ".join(AXIS_WORDS[a] for a in plan.undetermined)
        head = f"{what} {'is' if len(plan.undetermined) == 1 else 'are'} not determined or weak"
    else:
        axis, value = weakest_axis(plan.current, plan.target)
        head = (f"{plan.current_n} boards give 1-sigma {plan.current.rot_sigma_deg:.2f} deg, "
                f"{plan.current.trans_sigma_mm:.0f} mm; the weakest is {AXIS_WORDS[axis]} ({value})")
        if plan.current.meets(plan.target):
            return head + f": the target ({plan.target[0]:g} deg, {plan.target[1]:g} mm) is met"
    need = boards_to_add(plan)
    if need is None and plan.limited_by_systematic:
        return f"{head}: {systematic_words(plan)}; the most informative next: " + \
            "; ".join(describe_pose(q) for q in plan.poses)
    if need is None:
        return (f"{head}: the target ({plan.target[0]:g} deg, {plan.target[1]:g} mm) is not reached within "
                f"{MAX_PLAN_BOARDS} boards; the most informative next: "
                + "; ".join(describe_pose(q) for q in plan.poses))
    n_add = max(need, 1)
    named = plan.poses[:n_add]
    first = "" if len(named) == n_add else f", the first {len(named)}"
    return (f"{head}: add {n_add} board{'s' if n_add > 1 else ''}{first}: "
            + "; ".join(describe_pose(q) for q in named)
            + f" ({plan.to_target} boards in all reach {plan.target[0]:g} deg, {plan.target[1]:g} mm)")


__all__ = ["CRITERIA", "POSE_FIELDS", "Plan", "PlanError", "PlanRig", "Prediction", "SIGMA_NAMES", "as_pair",
           "boards_to_add", "describe_pose", "greedy", "limited_by_systematic", "name_undetermined", "plan_capture",
           "plan_summary", "plan_to_dict", "pool", "predict", "set_informations", "set_systematic",
           "systematic_words"]
