"""The capture planner's rig and the board poses it can propose: a rig description (camera, lidar, rough mounting,
board, workspace), the grid of board poses the operator can reach, and each pose's noise-free view by both
sensors (scan points on the true plane, corners at their true pixels), which the Fisher information needs.

Frames: ``{L}`` lidar (x forward, z up, scan plane z = 0), ``{C}`` camera, board plane z = 0. A board pose is
given as (distance, bearing, height, turn, lean, roll): the board centre (mean of the outline's vertices) at
``distance`` metres from the lidar origin, ``bearing`` radians counter-clockwise from the lidar x axis,
``height`` metres above the scan plane; the board stands vertical facing the camera (its normal the horizontal
line of sight from the camera's centre to the board centre, pattern rows horizontal), then turns by ``turn``
about the lidar's vertical axis (positive: counter-clockwise seen from above), leans by ``lean`` about its own
horizontal axis (positive: its top away from the camera) and rolls by ``roll`` about its normal. Units: metres,
radians inside; degrees only in the names that say so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.camera import Camera, CameraModel, project
from ..data.observations import BoardObservation, Observations
from ..geometry.beams import beam_bearings, board_ranges
from ..geometry.transforms import invert_T, make_T, rotvec_to_matrix
from ..model.board_error import BoardErrorScale
from ..refine.systematic import DEFAULT_PRIOR

POSE_FIELDS = ("distance_m", "bearing_deg", "height_m", "turn_deg", "lean_deg", "roll_deg")
"""The planner's board-pose parameters as they are shown and written (degrees at the edge)."""

REJECTIONS = ("behind the camera or closer than min_depth_m", "not wholly inside the image with its margin",
              "cut by the scan plane in fewer than min_points beams")
"""Why a board pose is not feasible, in the order tested."""


@dataclass(frozen=True)
class Workspace:
    """Where the operator can put the board, and the grid the planner searches.

    Ranges are (low, high) pairs; ``steps`` the grid points per range, in ``POSE_FIELDS`` order (a range with
    equal ends takes one point). Distances and heights in metres, angles in degrees (user-facing values).
    """

    distance_m: tuple[float, float] = (3.0, 6.0)
    bearing_deg: tuple[float, float] = (-30.0, 30.0)
    height_m: tuple[float, float] = (0.0, 0.0)
    turn_deg: tuple[float, float] = (-40.0, 40.0)
    lean_deg: tuple[float, float] = (-40.0, 40.0)
    roll_deg: tuple[float, float] = (0.0, 0.0)
    steps: tuple[int, ...] = (3, 7, 1, 5, 5, 1)

    def grid(self) -> np.ndarray:
        """(M,6) every grid pose, in ``POSE_FIELDS`` units (metres, degrees; bearings wrapped into [-180, 180):
        a range may run past 180 deg, behind the lidar)."""
        ranges = (self.distance_m, self.bearing_deg, self.height_m, self.turn_deg, self.lean_deg, self.roll_deg)
        axes = [np.unique(np.linspace(lo, hi, n if hi > lo else 1)) for (lo, hi), n in zip(ranges, self.steps,
                                                                                           strict=True)]
        out = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 6)
        out[:, 1] = np.mod(out[:, 1] + 180.0, 360.0) - 180.0
        return out


@dataclass(frozen=True, eq=False)
class PlanRig:
    """The rig as the planner needs it.

    Attributes:
        camera: intrinsics and image size; T_lidar_cam: the (rough) mounting, 4x4.
        outline: (V,2) board outline (board frame, metres); corners_board: (J,3) its pattern's corners.
        lidar_fov_deg, lidar_res_deg, lidar_max_range_m: the scan's beams.
        range_sigma_m: range noise std along a beam (metres); corner_sigma_px: corner noise std per coordinate
            (pixels; 0: board poses taken as exact, the range-only model).
        image_margin_px, min_depth_m, min_points: a proposed board lies wholly inside the image by this margin, this
            far in front of the camera, and is cut by the scan plane in at least this many beams.
        workspace: where the board can go.
        board_error: the per-board systematic error's scale (``calib_core.model.board_error``, metres) each board
            carries on top of the per-beam noise; default the calibration's prior (``refine.systematic``), the
            scale ``lidarcam`` assumes where the boards cannot estimate it. Zero: the per-beam noise alone.
    """

    camera: CameraModel
    T_lidar_cam: np.ndarray
    outline: np.ndarray
    corners_board: np.ndarray
    lidar_fov_deg: float = 180.0
    lidar_res_deg: float = 0.25
    lidar_max_range_m: float = 30.0
    range_sigma_m: float = 0.02
    corner_sigma_px: float = 0.5
    image_margin_px: float = 20.0
    min_depth_m: float = 0.5
    min_points: int = 10
    workspace: Workspace = field(default_factory=Workspace)
    board_error: BoardErrorScale = DEFAULT_PRIOR


def board_poses_lidar(rig: PlanRig, poses: np.ndarray) -> np.ndarray:
    """(M,4,4) ``T_lidar_board`` of planner poses (M,6) in ``POSE_FIELDS`` units (module docstring)."""
    p = np.atleast_2d(np.asarray(poses, float))
    d, bearing, h = p[:, 0], np.radians(p[:, 1]), p[:, 2]
    turn, lean, roll = np.radians(p[:, 3]), np.radians(p[:, 4]), np.radians(p[:, 5])
    horiz = np.sqrt(np.maximum(d**2 - h**2, 0.0))
    centre = np.column_stack([horiz * np.cos(bearing), horiz * np.sin(bearing), h])
    f = centre - rig.T_lidar_cam[:3, 3]
    f[:, 2] = 0.0
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    up = np.broadcast_to([0.0, 0.0, 1.0], f.shape)
    right = np.cross(f, up)                                     # board x: to the right as the camera sees it
    R0 = np.stack([right, -up, f], axis=2)                      # columns: board x, y (down), z (away)
    zero = np.zeros_like(turn)
    R = (rotvec_to_matrix(np.column_stack([zero, zero, turn]))
         @ rotvec_to_matrix(-lean[:, None] * right) @ R0 @ rotvec_to_matrix(np.column_stack([zero, zero, roll])))
    c_board = np.r_[np.asarray(rig.outline, float).mean(axis=0), 0.0]
    return make_T(R, centre - R @ c_board)


def feasibility(rig: PlanRig, T_lidar_board: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First failed test per pose (index into ``REJECTIONS``, -1 where feasible), the ranges (M,K) of every beam
    of ``beam_bearings`` to each board (inf where it misses or is out of range) and the bearings (K,)."""
    T = np.asarray(T_lidar_board, float).reshape(-1, 4, 4)
    T_cb = invert_T(rig.T_lidar_cam)[None] @ T
    outline = np.asarray(rig.outline, float)
    P = np.concatenate([np.column_stack([outline, np.zeros(len(outline))]), rig.corners_board])
    X = np.einsum("mij,vj->mvi", T_cb[:, :3, :3], P) + T_cb[:, None, :3, 3]
    reason = np.full(len(T), -1)
    if isinstance(rig.camera, Camera):
        bad = np.any(X[..., 2] < rig.min_depth_m, axis=1)
    else:   # a wide-angle model sees beside and behind the axis: its domain, at min_depth_m or more
        bad = ~np.all(rig.camera.valid(X) & (np.linalg.norm(X, axis=-1) >= rig.min_depth_m), axis=1)
    reason[bad] = 0
    with np.errstate(all="ignore"):
        uv = project(rig.camera, np.where(X[..., 2:] > 0, X, 1.0) if isinstance(rig.camera, Camera) else X)
    m, cam = rig.image_margin_px, rig.camera
    inside = np.all((uv[..., 0] >= m) & (uv[..., 0] <= cam.width - 1 - m) & (uv[..., 1] >= m)
                    & (uv[..., 1] <= cam.height - 1 - m), axis=1)
    reason[(reason < 0) & ~inside] = 1
    bearings = beam_bearings(rig.lidar_fov_deg, rig.lidar_res_deg)
    r = board_ranges(bearings, T, outline)
    r = np.where(r <= rig.lidar_max_range_m, r, np.inf)
    reason[(reason < 0) & (np.isfinite(r).sum(axis=1) < rig.min_points)] = 2
    return reason, r, bearings


def noise_free_views(rig: PlanRig, T_lidar_board: np.ndarray, ranges: np.ndarray, bearings: np.ndarray
                     ) -> Observations:
    """The boards ``T_lidar_board`` (M,4,4) as both sensors see them without noise: scan points at the beams'
    true ranges (``ranges`` (M,K) from ``feasibility``), corners at their true pixels; ``T_lidar_cam_true`` the
    rig's mounting. Every board must be feasible."""
    T_cb = invert_T(rig.T_lidar_cam)[None] @ np.asarray(T_lidar_board, float).reshape(-1, 4, 4)
    u = np.column_stack([np.cos(bearings), np.sin(bearings)])
    X = np.einsum("mij,vj->mvi", T_cb[:, :3, :3], rig.corners_board) + T_cb[:, None, :3, 3]
    uv = project(rig.camera, X)
    with_corners = rig.corner_sigma_px > 0
    boards = tuple(BoardObservation(T_cb[i], rig.outline, ranges[i, hit, None] * u[hit],
                                    uv[i] if with_corners else None, rig.corners_board if with_corners else None)
                   for i, hit in enumerate(np.isfinite(ranges)))
    return Observations(boards, rig.T_lidar_cam, {"generator": "lidarcam.plan"}, rig.camera)


def rig_from_observations(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float, corner_sigma_px: float,
                          base: PlanRig | None = None, board_error: BoardErrorScale = DEFAULT_PRIOR) -> PlanRig:
    """The planner's rig of a captured board set: its camera, board (outline and corners of its first board),
    the extrinsic ``T_lidar_cam`` (e.g. its calibration) and the noise stds and per-board systematic scale
    ``board_error`` given. With ``base`` (a rig description) the lidar, limits and workspace are ``base``'s;
    otherwise the lidar's resolution is the median bearing step of the scans, and the workspace spans the captured
    boards' distances (-10 %, +10 %) and bearings (+-10 deg, about their circular mean: boards around 180 deg,
    behind the lidar, span that side only) with the default tilts, the boards rolled in their plane as most
    captured ones are (to the nearest quarter turn: ``captured_roll_deg``; so a grid written 5x8 instead of 8x5
    gives the same plan). ValueError without camera intrinsics."""
    if obs.camera is None and base is None:
        raise ValueError("the observations carry no camera intrinsics: give a rig description too")
    b0 = obs.boards[0]
    outline = b0.outline
    if outline is None:                 # no outline known: the corners' extent
        if b0.corners_board is None:
            raise ValueError("the first board has neither an outline nor corners: give a rig description")
        lo, hi = b0.corners_board[:, :2].min(axis=0), b0.corners_board[:, :2].max(axis=0)
        outline = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    corners = b0.corners_board if b0.corners_board is not None else np.column_stack([outline,
                                                                                     np.zeros(len(outline))])
    T = np.asarray(T_lidar_cam, float)
    camera = obs.camera if obs.camera is not None else base.camera
    if base is not None:
        return PlanRig(camera, T, outline, corners, base.lidar_fov_deg, base.lidar_res_deg, base.lidar_max_range_m,
                       range_sigma_m, corner_sigma_px, base.image_margin_px, base.min_depth_m, base.min_points,
                       base.workspace, board_error)
    steps = [np.diff(np.sort(np.arctan2(b.scan[:, 1], b.scan[:, 0]))) for b in obs.boards]
    steps = np.concatenate(steps)
    res_deg = float(np.degrees(np.median(steps[steps > 1e-6]))) if np.any(steps > 1e-6) else 0.25
    T_lb = T[None] @ np.array([bd.T_cam_board for bd in obs.boards])
    c = T_lb[:, :3, :3] @ np.r_[outline.mean(axis=0), 0.0] + T_lb[:, :3, 3]
    dist, bearing = np.linalg.norm(c[:, :2], axis=1), np.arctan2(c[:, 1], c[:, 0])
    mid = np.degrees(np.arctan2(np.mean(np.sin(bearing)), np.mean(np.cos(bearing))))   # boards behind: near 180
    rel = np.mod(np.degrees(bearing) - mid + 180.0, 360.0) - 180.0
    roll = captured_roll_deg(rig_roll_probe(camera, T, outline, corners), T_lb)
    ws = Workspace(distance_m=(0.9 * dist.min(), 1.1 * dist.max()),
                   bearing_deg=(mid + rel.min() - 10.0, mid + rel.max() + 10.0), roll_deg=(roll, roll))
    fov = min(360.0, 2.0 * max(abs(ws.bearing_deg[0]), abs(ws.bearing_deg[1])) + 40.0)
    return PlanRig(camera, T, outline, corners, fov, res_deg, 1.5 * float(dist.max()) + 5.0, range_sigma_m,
                   corner_sigma_px, workspace=ws, board_error=board_error)


def rig_roll_probe(camera: Camera, T_lidar_cam: np.ndarray, outline: np.ndarray, corners: np.ndarray) -> PlanRig:
    """A rig with the board and mounting given, to place boards with ``board_poses_lidar``."""
    return PlanRig(camera, T_lidar_cam, outline, corners)


def captured_roll_deg(rig: PlanRig, T_lidar_board: np.ndarray) -> float:
    """The in-plane roll (degrees, a multiple of 90) most captured boards ``T_lidar_board`` (N,4,4) have against the
    planner's upright board at their place (``board_poses_lidar`` with no turn, lean or roll): each board's roll
    ``atan2(x . down, x . right)`` of its x axis, rounded to a quarter turn; the most common (ties: the smallest)."""
    T = np.asarray(T_lidar_board, float).reshape(-1, 4, 4)
    c = T[:, :3, :3] @ np.r_[np.asarray(rig.outline, float).mean(axis=0), 0.0] + T[:, :3, 3]
    dist, bearing = np.linalg.norm(c, axis=1), np.degrees(np.arctan2(c[:, 1], c[:, 0]))
    upright = board_poses_lidar(rig, np.column_stack([dist, bearing, c[:, 2], np.zeros((len(T), 3))]))
    x = T[:, :3, 0]
    angle = np.degrees(np.arctan2(np.sum(x * upright[:, :3, 1], axis=1), np.sum(x * upright[:, :3, 0], axis=1)))
    quarter = np.mod(np.rint(angle / 90.0).astype(int), 4)
    k = int(np.argmax(np.bincount(quarter, minlength=4)))
    return float(90 * k if k < 3 else -90)

