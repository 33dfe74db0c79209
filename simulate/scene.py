"""Random calibration scenes: the true extrinsic and board poses drawn by rejection sampling.

Frames: ``{L}`` lidar (x forward, z up, scan plane z = 0), ``{C}`` camera (z optical axis, y down),
``{W}`` board (plane z = 0, z pointing away from the camera). Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix

from .camera import BoardSpec, camera_matrix
from .lens import edge_points, in_view, is_default, true_camera
from .lidar import beam_bearings, board_ranges, scan_chords
from .options import SimOptions

# Nominal axis change, maps camera axes into the lidar frame: camera z -> lidar x, x -> -y, y -> -z.
R_LIDAR_CAM_NOMINAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

# Rejection reasons, in the order they are tested.
REASONS = (
    "camera: board behind the camera or closer than min_depth_m",
    "camera: board not wholly inside the image (image_margin_px)",
    "lidar: the scan plane misses the board",
    "lidar: a chord end outside lidar_fov_deg or beyond lidar_max_range_m",
    "lidar: fewer than min_points_per_board points on the board",
    "lidar: overlaps an earlier board in bearing (shared_scan)",
)


class SceneError(RuntimeError):
    """No scene satisfying the options could be drawn (names the constraint that failed most often)."""


@dataclass(frozen=True, eq=False)
class Scene:
    """The true geometry of one simulated problem.

    Attributes:
        T_lidar_cam: 4x4, maps camera points into the lidar frame.
        T_lidar_board: (N,4,4) board poses in the lidar frame.
        outline: (4,2) board outline in its own frame, metres.
        margins_m: (N,) per board, the margin of the physical board beyond its printed pattern (metres) when the
            options draw one (``simulate.rig``; the board's outline is then ``rig.physical_outline``), else None.
    """

    T_lidar_cam: np.ndarray
    T_lidar_board: np.ndarray
    outline: np.ndarray
    margins_m: np.ndarray | None = None

    @property
    def T_cam_board(self) -> np.ndarray:
        """(N,4,4) true board poses in the camera frame."""
        return invert_T(self.T_lidar_cam)[None] @ self.T_lidar_board


def random_unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n,3) directions uniform on the sphere."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def sample_extrinsic(options: SimOptions, rng: np.random.Generator) -> np.ndarray:
    """True ``T_lidar_cam`` (4x4): nominal axis change times a rotation of random axis and angle uniform in
    [0, extrinsic_rot_deg] (applied in the camera frame); translation of random direction, length uniform in
    [extrinsic_trans_min_m, extrinsic_trans_max_m]."""
    axis = random_unit_vectors(rng, 1)[0]
    angle = np.radians(rng.uniform(0.0, options.extrinsic_rot_deg))
    R = R_LIDAR_CAM_NOMINAL @ rotvec_to_matrix(angle * axis)
    t = random_unit_vectors(rng, 1)[0] * rng.uniform(options.extrinsic_trans_min_m, options.extrinsic_trans_max_m)
    return make_T(R, t)


def sample_board_candidates(options: SimOptions, cam_centre_L: np.ndarray, rng: np.random.Generator,
                            n: int) -> np.ndarray:
    """``n`` candidate board poses ``T_lidar_board`` (n,4,4), before the visibility checks.

    Centre: distance from the lidar uniform in [dist_min_m, dist_max_m], bearing uniform within
    +-bearing_spread_deg/2, height uniform within +-center_height_max_m. Normal (board z, pointing away from
    the camera) uniform on the cap of half-angle max_tilt_deg around the camera's line of sight to the centre.
    In-plane: board y along the lidar's down direction projected on the board, then rolled about the normal
    by an angle uniform within +-max_roll_deg.
    """
    o = options
    dist = rng.uniform(o.dist_min_m, o.dist_max_m, n)
    bearing = np.radians(rng.uniform(-o.bearing_spread_deg / 2, o.bearing_spread_deg / 2, n))
    height = rng.uniform(-o.center_height_max_m, o.center_height_max_m, n)
    horiz = np.sqrt(dist**2 - height**2)
    centre = np.column_stack([horiz * np.cos(bearing), horiz * np.sin(bearing), height])
    los = centre - cam_centre_L
    los /= np.linalg.norm(los, axis=1, keepdims=True)
    # orthonormal basis (a, b) perpendicular to the line of sight
    a = np.cross(los, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(los, a)
    cos_tilt = rng.uniform(np.cos(np.radians(o.max_tilt_deg)), 1.0, n)
    sin_tilt = np.sqrt(1.0 - cos_tilt**2)
    az = rng.uniform(0.0, 2 * np.pi, n)
    normal = cos_tilt[:, None] * los + sin_tilt[:, None] * (np.cos(az)[:, None] * a + np.sin(az)[:, None] * b)
    down = np.array([0.0, 0.0, -1.0])
    y0 = down - (normal @ down)[:, None] * normal
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    x0 = np.cross(y0, normal)
    roll = np.radians(rng.uniform(-o.max_roll_deg, o.max_roll_deg, n))
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x = c * x0 + s * y0
    y = -s * x0 + c * y0
    R = np.stack([x, y, normal], axis=2)
    half = o.board_size_m / 2.0
    t = centre - R[:, :, 0] * half - R[:, :, 1] * half
    return make_T(R, t)


def check_candidates(options: SimOptions, T_lidar_cam: np.ndarray, T_lidar_board: np.ndarray,
                     bearings: np.ndarray, taken: list[tuple[float, float]]) -> np.ndarray:
    """First failed constraint per candidate (index into REASONS), -1 where a candidate passes them all.

    ``taken``: bearing intervals (radians) of boards already placed, checked when ``shared_scan``.
    """
    o = options
    outline = BoardSpec.of(o).outline()
    n = len(T_lidar_board)
    reason = np.full(n, -1)

    def mark(bad: np.ndarray, code: int) -> None:
        reason[(reason < 0) & bad] = code

    T_cam_board = invert_T(T_lidar_cam)[None] @ T_lidar_board
    P = np.einsum("mij,vj->mvi", T_cam_board[:, :3, :3], np.column_stack([outline, np.zeros(len(outline))]))
    P += T_cam_board[:, None, :3, 3]
    if is_default(o):
        mark(np.any(P[..., 2] < o.min_depth_m, axis=1), 0)
        K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (P @ K.T)[..., :2] / P[..., 2:3]
        m = o.image_margin_px
        inside = ((uv[..., 0] >= m) & (uv[..., 0] <= o.cam_width - 1 - m)
                  & (uv[..., 1] >= m) & (uv[..., 1] <= o.cam_height - 1 - m))
        mark(~np.all(inside, axis=1), 1)
    else:   # through the lens: the outline's edges (a lens bends them), every point in the model and the image
        mark(np.any(np.linalg.norm(P, axis=2) < o.min_depth_m, axis=1), 0)
        E = np.einsum("mij,vj->mvi", T_cam_board[:, :3, :3], edge_points(outline)) + T_cam_board[:, None, :3, 3]
        mark(~in_view(true_camera(o), E, o.image_margin_px, o.min_depth_m), 1)
    chords = scan_chords(T_lidar_board, outline)
    mark(np.isnan(chords[:, 0, 0]), 2)
    ang = np.arctan2(chords[..., 1], chords[..., 0])                 # (n,2), ordered
    rng_end = np.linalg.norm(chords, axis=2)
    half_fov = np.radians(o.lidar_fov_deg) / 2
    with np.errstate(invalid="ignore"):
        bad_end = ((ang[:, 0] <= -half_fov) | (ang[:, 1] >= half_fov) | (ang[:, 1] - ang[:, 0] >= np.pi)
                   | np.any(rng_end > o.lidar_max_range_m, axis=1))
    mark(bad_end, 3)
    todo = reason < 0
    if np.any(todo):
        hits = np.isfinite(board_ranges(bearings, T_lidar_board[todo], outline)).sum(axis=1)
        idx = np.flatnonzero(todo)
        reason[idx[hits < o.min_points_per_board]] = 4
    if o.shared_scan and taken:
        step = np.radians(o.lidar_res_deg)
        lo, hi = ang[:, 0] - step, ang[:, 1] + step
        overlap = np.zeros(n, bool)
        for a0, a1 in taken:
            overlap |= (lo <= a1) & (hi >= a0)
        mark(overlap, 5)
    return reason


def sample_scene(options: SimOptions, rng: np.random.Generator, accept=None) -> Scene:
    """A random scene satisfying every constraint of ``options``; raises SceneError naming the constraint
    that failed most often when a board cannot be placed within ``max_attempts`` candidates.

    ``accept(T_lidar_cam, T_lidar_board) -> bool``: optional extra test per board (see ``draw_board``).
    """
    o = options
    T_lidar_cam = sample_extrinsic(o, rng)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    boards: list[np.ndarray] = []
    taken: list[tuple[float, float]] = []
    for i in range(o.n_boards):
        extra = None if accept is None else (lambda T, _c=T_lidar_cam: accept(_c, T))
        boards.append(draw_board(o, T_lidar_cam, bearings, taken, rng, board_index=i, accept=extra))
        ch = scan_chords(boards[-1], BoardSpec.of(o).outline())[0]
        taken.append(tuple(np.arctan2(ch[:, 1], ch[:, 0])))
    return Scene(T_lidar_cam, np.array(boards), BoardSpec.of(o).outline())


def draw_board(options: SimOptions, T_lidar_cam: np.ndarray, bearings: np.ndarray,
               taken: list[tuple[float, float]], rng: np.random.Generator, board_index: int = 0,
               accept=None) -> np.ndarray:
    """One board pose ``T_lidar_board`` (4x4) by rejection, ``candidate_batch`` candidates at a time.

    ``accept(T_lidar_board) -> bool`` is an optional extra test (e.g. the checkerboard is detected); its
    refusals count as attempts. Raises SceneError after ``max_attempts`` candidates.
    """
    o = options
    counts = np.zeros(len(REASONS) + 1, int)
    tried = 0
    while tried < o.max_attempts:
        n = min(o.candidate_batch, o.max_attempts - tried)
        cand = sample_board_candidates(o, T_lidar_cam[:3, 3], rng, n)
        reason = check_candidates(o, T_lidar_cam, cand, bearings, taken)
        for j in range(n):
            tried += 1
            if reason[j] >= 0:
                counts[reason[j]] += 1
                continue
            if accept is None or accept(cand[j]):
                return cand[j]
            counts[-1] += 1
    names = list(REASONS) + ["camera: the extra acceptance test (checkerboard detection) failed"]
    worst = int(np.argmax(counts))
    detail = ", ".join(f"{names[k]}: {c}" for k, c in enumerate(counts) if c)
    raise SceneError(f"board {board_index}: no valid pose in {o.max_attempts} attempts; most often failed: "
                     f"{names[worst]} ({detail})")
