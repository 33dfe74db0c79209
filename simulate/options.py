"""``SimOptions``: the flat, frozen settings of the simulator (also the Hydra structured-config schema).

Units: metres and radians inside the code; the option names say where a value is in mm, deg or px.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import asdict, dataclass, fields

POSE_MODES = ("exact", "pixel", "image")


@dataclass(frozen=True)
class SimOptions:
    """Every assumption of the simulated calibration scene (docs/METHOD.md), one primitive per field.

    Scene: boards are separate captures of one board moved to ``n_boards`` poses (``shared_scan=False``,
    so boards never occlude each other), or all in one scan (``shared_scan=True``: their bearing intervals
    from the lidar must not overlap, and the ray caster lets the nearest hit win anyway).

    Board: a square of side ``board_size_m`` (outline ``[[0,0],[c,0],[c,c],[0,c]]``, board plane z = 0)
    carrying a checkerboard of ``board_squares_x`` x ``board_squares_y`` squares of side
    ``checker_square_m``, centred on the board (see ``simulate.camera.checkerboard_corners``).

    Placement: the board centre lies at ``dist_min_m``..``dist_max_m`` from the lidar, at a bearing within
    +-``bearing_spread_deg``/2 of the lidar x axis, at a height within +-``center_height_max_m`` of the scan
    plane; the board normal is within ``max_tilt_deg`` of the camera's line of sight to the board centre,
    rotated about that normal by up to +-``max_roll_deg``.

    Lidar: beams every ``lidar_res_deg`` across ``lidar_fov_deg`` centred on x, ranges up to
    ``lidar_max_range_m``, zero-mean Gaussian range noise of standard deviation ``noise_mm`` along each beam
    (the paper's "variance 20 mm" read as a standard deviation).

    Camera: pinhole, ``focal_px``, ``cam_width`` x ``cam_height``, principal point at the image centre
    ((W-1)/2, (H-1)/2) in OpenCV's pixel-centre convention; ``cam_model`` and ``cam_params`` choose the lens
    (``simulate.lens``: any model of ``calib_core.data.cameras`` on that K; ``image`` mode renders through it,
    ``simulate.lens_render``; the pose is then fitted through the model). ``pose_mode``: ``exact`` (true board
    poses), ``pixel`` (project the inner corners, add ``pixel_noise_px`` Gaussian noise, solvePnP IPPE), ``image``
    (render at ``render_supersample`` x supersampling, add ``image_noise_std`` grey-level noise, detect with
    findChessboardCornersSB, solvePnP IPPE).
    Boards must project at least ``image_margin_px`` inside the
    image and lie at least ``min_depth_m`` in front of the camera.

    Extrinsic: ``T_lidar_cam`` = nominal axis change (camera z -> lidar x, x -> -y, y -> -z) times a rotation
    of random axis and angle uniform in [0, ``extrinsic_rot_deg``]; translation of random direction and
    length uniform in [``extrinsic_trans_min_m``, ``extrinsic_trans_max_m``].

    Sampling: each board is drawn by rejection, ``candidate_batch`` candidates at a time, at most
    ``max_attempts`` candidates per board; a board needs ``min_points_per_board`` lidar points.

    Contamination (all off by default; see ``simulate.outliers``): ``wrong_segments`` boards get, instead of
    their scan, a straight segment of another object at a similar range (what a segmenter returns when it picks
    a cabinet next to the board); ``gross_outlier_frac`` adds that share of each board's point count as spurious
    returns at 1-30 m on beams within the board's bearing span; ``mixed_pixel_frac`` adds that share as
    mixed pixels on the beams just beyond the board's ends, between the board and a background 0.2-3 m behind.

    Rig conditions (all off by default; see ``simulate.rig``): with ``board_margin_max_m > 0`` the physical board
    of each view is the printed checkerboard's extent (``board_squares_x`` x ``board_squares_y`` squares of
    ``checker_square_m``) grown on every side by a margin drawn per board, uniform in
    [``board_margin_min_m``, ``board_margin_max_m``] metres; ``board_size_m`` then only bounds it (the square in
    which the scene places and checks a board; the margin must fit in it), the lidar sees the physical board and the
    file's outline is the printed pattern's with ``outline_kind: lower_bound`` (what a user without the board's
    size has, as the importers write), or the exact physical one with ``outline_known``. Intrinsics error (``pose_mode``
    pixel or image only; ``exact`` has no camera): once per trial, fx and fy are each scaled by
    ``1 + N(0, focal_error_rel)``, cx and cy moved by ``N(0, principal_point_error_px)`` pixels and, with
    ``distortion_error > 0``, k1, k2, p1, p2 drawn from ``N(0, distortion_error)`` (the true camera has none); the
    file's camera is that erroneous one, every ``T_cam_board`` is the PnP pose with it, and with
    ``std_intrinsics_known`` the file states the drawing's 1-sigma as ``camera.std_intrinsics``.
    """

    n_boards: int = 6
    board_size_m: float = 1.0
    board_squares_x: int = 7
    board_squares_y: int = 6
    checker_square_m: float = 0.12
    dist_min_m: float = 3.0
    dist_max_m: float = 6.0
    bearing_spread_deg: float = 60.0
    center_height_max_m: float = 0.3
    max_tilt_deg: float = 45.0
    max_roll_deg: float = 180.0
    shared_scan: bool = False
    lidar_res_deg: float = 0.25
    lidar_fov_deg: float = 180.0
    lidar_max_range_m: float = 30.0
    noise_mm: float = 20.0
    cam_width: int = 800
    cam_height: int = 600
    focal_px: float = 800.0
    image_margin_px: float = 5.0
    min_depth_m: float = 0.5
    pose_mode: str = "exact"
    pixel_noise_px: float = 0.5
    image_noise_std: float = 2.0
    render_supersample: int = 4
    extrinsic_rot_deg: float = 5.0
    extrinsic_trans_min_m: float = 0.05
    extrinsic_trans_max_m: float = 0.30
    min_points_per_board: int = 10
    max_attempts: int = 1000
    candidate_batch: int = 64
    wrong_segments: int = 0
    gross_outlier_frac: float = 0.0
    mixed_pixel_frac: float = 0.0
    board_margin_min_m: float = 0.0
    board_margin_max_m: float = 0.0
    outline_known: bool = False
    focal_error_rel: float = 0.0
    principal_point_error_px: float = 0.0
    distortion_error: float = 0.0
    std_intrinsics_known: bool = True
    cam_model: str = "pinhole-radtan"
    cam_params: str = ""

    def __post_init__(self) -> None:
        def need(cond: bool, msg: str) -> None:
            if not cond:
                raise ValueError(f"SimOptions: {msg}")

        for f in fields(self):
            v = getattr(self, f.name)
            kind = {"int": int, "float": (int, float), "str": str, "bool": bool}[f.type]
            need(isinstance(v, kind) and (f.type == "bool" or not isinstance(v, bool)),
                 f"{f.name} must be {f.type}, got {v!r}")
            if f.type == "float":
                need(v == v and abs(v) != float("inf"), f"{f.name} must be finite, got {v!r}")
                object.__setattr__(self, f.name, float(v))  # 1 and 1.0 must hash (and seed) alike
        need(self.n_boards >= 1, f"n_boards must be >= 1, got {self.n_boards}")
        need(self.board_size_m > 0, f"board_size_m must be > 0, got {self.board_size_m}")
        need(self.board_squares_x >= 2 and self.board_squares_y >= 2,
             f"board_squares_x/y must be >= 2, got {self.board_squares_x}x{self.board_squares_y}")
        need(self.checker_square_m > 0, f"checker_square_m must be > 0, got {self.checker_square_m}")
        need(max(self.board_squares_x, self.board_squares_y) * self.checker_square_m <= self.board_size_m + 1e-12,
             f"checkerboard {self.board_squares_x}x{self.board_squares_y} x {self.checker_square_m} m "
             f"does not fit on a board of {self.board_size_m} m")
        need(0 < self.dist_min_m <= self.dist_max_m,
             f"need 0 < dist_min_m <= dist_max_m, got {self.dist_min_m}, {self.dist_max_m}")
        need(0 <= self.bearing_spread_deg <= 360,
             f"bearing_spread_deg must be in [0, 360], got {self.bearing_spread_deg}")
        need(0 <= self.center_height_max_m < self.dist_min_m,
             f"center_height_max_m must be in [0, dist_min_m), got {self.center_height_max_m}")
        need(0 <= self.max_tilt_deg < 90, f"max_tilt_deg must be in [0, 90), got {self.max_tilt_deg}")
        need(0 <= self.max_roll_deg <= 180, f"max_roll_deg must be in [0, 180], got {self.max_roll_deg}")
        need(self.lidar_res_deg > 0, f"lidar_res_deg must be > 0, got {self.lidar_res_deg}")
        need(0 < self.lidar_fov_deg <= 360, f"lidar_fov_deg must be in (0, 360], got {self.lidar_fov_deg}")
        need(self.lidar_max_range_m > 0, f"lidar_max_range_m must be > 0, got {self.lidar_max_range_m}")
        need(self.noise_mm >= 0, f"noise_mm must be >= 0, got {self.noise_mm}")
        need(self.cam_width >= 16 and self.cam_height >= 16,
             f"cam_width/cam_height must be >= 16, got {self.cam_width}x{self.cam_height}")
        need(self.focal_px > 0, f"focal_px must be > 0, got {self.focal_px}")
        need(self.image_margin_px >= 0, f"image_margin_px must be >= 0, got {self.image_margin_px}")
        need(self.min_depth_m > 0, f"min_depth_m must be > 0, got {self.min_depth_m}")
        need(self.pose_mode in POSE_MODES, f"pose_mode must be one of {POSE_MODES}, got {self.pose_mode!r}")
        need(self.pixel_noise_px >= 0, f"pixel_noise_px must be >= 0, got {self.pixel_noise_px}")
        need(self.image_noise_std >= 0, f"image_noise_std must be >= 0, got {self.image_noise_std}")
        need(1 <= self.render_supersample <= 16,
             f"render_supersample must be in [1, 16], got {self.render_supersample}")
        need(self.extrinsic_rot_deg >= 0, f"extrinsic_rot_deg must be >= 0, got {self.extrinsic_rot_deg}")
        need(0 <= self.extrinsic_trans_min_m <= self.extrinsic_trans_max_m,
             f"need 0 <= extrinsic_trans_min_m <= extrinsic_trans_max_m, got "
             f"{self.extrinsic_trans_min_m}, {self.extrinsic_trans_max_m}")
        need(self.min_points_per_board >= 2, f"min_points_per_board must be >= 2, got {self.min_points_per_board}")
        need(self.max_attempts >= 1, f"max_attempts must be >= 1, got {self.max_attempts}")
        need(self.candidate_batch >= 1, f"candidate_batch must be >= 1, got {self.candidate_batch}")
        need(0 <= self.wrong_segments <= self.n_boards,
             f"wrong_segments must be in [0, n_boards], got {self.wrong_segments}")
        need(0 <= self.gross_outlier_frac <= 1, f"gross_outlier_frac must be in [0, 1], got {self.gross_outlier_frac}")
        need(0 <= self.mixed_pixel_frac <= 1, f"mixed_pixel_frac must be in [0, 1], got {self.mixed_pixel_frac}")
        need(0 <= self.board_margin_min_m <= self.board_margin_max_m,
             f"need 0 <= board_margin_min_m <= board_margin_max_m, got {self.board_margin_min_m}, "
             f"{self.board_margin_max_m}")
        pattern = max(self.board_squares_x, self.board_squares_y) * self.checker_square_m
        need(pattern + 2 * self.board_margin_max_m <= self.board_size_m + 1e-12,
             f"the pattern ({pattern:g} m) with a margin of {self.board_margin_max_m:g} m per side does not fit in "
             f"board_size_m = {self.board_size_m:g} m")
        need(not (self.board_margin_max_m > 0 and self.shared_scan), "board margins need shared_scan false")
        for name in ("focal_error_rel", "principal_point_error_px", "distortion_error"):
            need(getattr(self, name) >= 0, f"{name} must be >= 0, got {getattr(self, name)}")
        need(self.focal_error_rel < 0.1, f"focal_error_rel must be < 0.1, got {self.focal_error_rel}")
        need(self.pose_mode != "exact" or not self.intrinsics_error_on,
             "an intrinsics error needs pose_mode pixel or image (exact poses come from no camera)")
        if (self.cam_model, self.cam_params) != (CAMERA_DEFAULTS["cam_model"], CAMERA_DEFAULTS["cam_params"]):
            from .lens import true_camera  # the lens models; ValueError naming the option when not valid

            true_camera(self)
            need(self.distortion_error == 0 or self.cam_model == "pinhole-radtan",
                 "distortion_error draws OpenCV coefficients: it needs cam_model pinhole-radtan")

    @property
    def intrinsics_error_on(self) -> bool:
        """True when some intrinsics error is drawn."""
        return self.focal_error_rel > 0 or self.principal_point_error_px > 0 or self.distortion_error > 0

    def to_dict(self) -> dict:
        """The options as a plain JSON-able dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> SimOptions:
        """Options from a dict (e.g. ``meta["options"]`` or a Hydra config); unknown keys are an error."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f"SimOptions: unknown option(s) {unknown}")
        return cls(**d)


CONTAMINATION_DEFAULTS = {"wrong_segments": 0, "gross_outlier_frac": 0.0, "mixed_pixel_frac": 0.0}
"""The contamination options and their (off) defaults. ``settings_hash`` (the seed of a trial's geometry and
noise) never includes them, so a contaminated trial is its clean twin plus the contamination, and settings
without contamination keep the random streams they had before these options existed; result-folder keys
include them only when on (``hashed_settings``)."""


RIG_DEFAULTS = {"board_margin_min_m": 0.0, "board_margin_max_m": 0.0, "outline_known": False, "focal_error_rel": 0.0,
                "principal_point_error_px": 0.0, "distortion_error": 0.0, "std_intrinsics_known": True}
"""The rig-condition options and their (off) defaults. At these defaults they are left out of ``settings_hash`` and
``hashed_settings``, so settings that leave them off keep the random streams and result-folder keys they had
before these options existed; when on they are part of both."""


CAMERA_DEFAULTS = {"cam_model": "pinhole-radtan", "cam_params": ""}
"""The lens options (``simulate.lens``) and their defaults (the distortion-free pinhole); like the rig options, left
out of ``settings_hash`` and ``hashed_settings`` at these values."""


def _at_default(k: str, v) -> bool:
    for defaults in (CONTAMINATION_DEFAULTS, RIG_DEFAULTS, CAMERA_DEFAULTS):
        if k in defaults and v == defaults[k]:
            return True
    return False


def hashed_settings(d: dict) -> dict:
    """``d`` (SimOptions fields) without the contamination and rig options that are at their off defaults."""
    return {k: v for k, v in d.items() if not _at_default(k, v)}


def contamination_on(options: SimOptions) -> bool:
    """True when some contamination option is not at its off default."""
    return any(getattr(options, k) != v for k, v in CONTAMINATION_DEFAULTS.items())


def settings_hash(options: SimOptions) -> int:
    """Stable 32-bit hash of the options: CRC32 of their canonical JSON (sorted keys, repr floats), without the
    contamination options (``CONTAMINATION_DEFAULTS``) and without the rig options at their off defaults
    (``RIG_DEFAULTS``)."""
    d = {k: v for k, v in options.to_dict().items() if k not in CONTAMINATION_DEFAULTS and not _at_default(k, v)}
    text = json.dumps(d, sort_keys=True, separators=(",", ":"))
    return zlib.crc32(text.encode("utf-8"))


def contamination_hash(options: SimOptions) -> int:
    """CRC32 of the contamination options alone (seeds the contamination stream of a trial)."""
    d = {k: getattr(options, k) for k in sorted(CONTAMINATION_DEFAULTS)}
    return zlib.crc32(json.dumps(d, sort_keys=True, separators=(",", ":")).encode("utf-8"))
