"""What scan and image extraction is told (``ExtractOptions``), reports per pose (``PoseDiagnostics``) and raises
(``ExtractionError``, ``AmbiguousSegment``); the steps live in ``lidarcam.rig.detect`` (camera side),
``lidarcam.rig.segment`` (scan
side) and ``lidarcam.rig.extract`` (per pose and per dataset). Metres, radians, pixels."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from calib_core.data.observations import OUTLINE_KINDS
from calib_core.errors import LidarcamError


class ExtractionError(LidarcamError):
    """A pose's board or scan segment could not be found; the message is the skip reason."""


class AmbiguousSegment(ExtractionError):
    """Several scan segments fit the board about equally; ``segments`` holds their (i0, i1) index ranges, best
    first, so that a later pass (``extract``) can choose with the extrinsic of the unambiguous poses."""

    def __init__(self, message: str, segments: list[tuple[int, int]]) -> None:
        super().__init__(message)
        self.segments = segments


CURVATURE_CHI2 = 15.14
"""A segment is refused as not straight when a parabola along its line explains more of its scatter than a line
by more than this chi-square(1) quantile (1 - 1e-4) in units of the range noise: an arc, not a board."""


@dataclass(frozen=True)
class ExtractOptions:
    """Thresholds of the extraction (metres, radians, pixels).

    Attributes:
        max_offset_m: bound on the lidar-camera separation; a board point's lidar range must lie within the
            camera's distances to the board +- this.
        max_reproj_px: a detection whose corner reprojection RMS exceeds this is rejected.
        range_sigma_m: assumed lidar range noise (1 sigma), used in the breakpoint and split thresholds.
        breakpoint_lambda_deg: Borges-Aldon breakpoint angle (smaller = more permissive of oblique surfaces).
        split_tol_m: split a segment where a point lies further than this from its chord; merge neighbours whose
            union fits a line within it. 0 means ``max(0.05, 4 * range_sigma_m)``.
        min_points: fewest scan points on a board.
        min_length_frac: shortest accepted segment, as a fraction of the outline's shorter side.
        length_slack_m: accepted excess of the segment length over the board's diagonal (noise at the ends).
        background_tol_m: a point whose range is not shorter than the background's by this much is background.
        scan_plane_normal_cam: assumed normal of the scan plane in the camera frame for the expected chord
            (default: camera y, i.e. a lidar scanning roughly parallel to the camera's x-z plane); ranking only.
        chord_weight: weight of the expected-chord term in the ranking (0 disables it).
        detector_flags: extra ``cv2.CALIB_CB_*`` flags for findChessboardCornersSB (default: normalise + exhaustive
            + accuracy).
        auto_background: with no background.csv, drop the points that stay put across the poses
        (lidarcam.rig.multipose).
        static_tol_m: range agreement for a point to count as the same return in another pose.
        max_curvature_chi2: a segment whose parabola fit beats the line by more than this (chi-square(1) units of
            the range noise) is refused as an arc (``CURVATURE_CHI2``; raise it for a lidar whose range depends on
            the surface's colour).
        outline_kind: what ``board.outline`` says of the physical board, written into the observations
            (``calib_core.data.observations.OUTLINE_KINDS``): ``exact`` (default), ``lower_bound`` (the board may be
            larger, e.g. a printed sheet on a larger board: segments longer than the outline's chord are not
            penalised, up to ``max_board_m``) or ``none`` (as ``lower_bound`` for the segment search; the
            observations carry no outline).
        max_board_m: longest accepted segment when the outline is not known.
        skip_ambiguous: skip a pose whose two best segments score within ``ambiguity_margin`` (else keep the best
            with a note).
        merge_duplicates: poses whose camera views agree within ``duplicate_deg`` / ``duplicate_m`` are one board
            pose captured several times: they become one board holding all their scan points.
        resolve_ratio: an ambiguous pose is resolved by the extrinsic of the unambiguous poses when its best
            candidate's point-to-plane RMS is below ``split_tol`` and below this times the next one's.
    """

    max_offset_m: float = 0.5
    max_reproj_px: float = 2.0
    range_sigma_m: float = 0.02
    breakpoint_lambda_deg: float = 10.0
    split_tol_m: float = 0.0
    min_points: int = 5
    min_length_frac: float = 0.25
    length_slack_m: float = 0.1
    background_tol_m: float = 0.1
    scan_plane_normal_cam: tuple[float, float, float] = (0.0, 1.0, 0.0)
    chord_weight: float = 0.5
    detector_flags: int | None = None
    auto_background: bool = True
    static_tol_m: float = 0.03
    outline_kind: str = "exact"
    max_curvature_chi2: float = CURVATURE_CHI2
    max_board_m: float = 2.0
    skip_ambiguous: bool = True
    ambiguity_margin: float = 0.1
    merge_duplicates: bool = True
    duplicate_deg: float = 1.5
    duplicate_m: float = 0.015
    resolve_ratio: float = 0.5

    def __post_init__(self) -> None:
        if self.outline_kind not in OUTLINE_KINDS:
            raise ExtractionError(f"outline_kind must be one of {', '.join(OUTLINE_KINDS)}, got {self.outline_kind!r}")

    @property
    def outline_known(self) -> bool:
        """True when the outline is the board's edge (``outline_kind`` ``exact``): the segment may not exceed it."""
        return self.outline_kind == "exact"

    @property
    def split_tol(self) -> float:
        return self.split_tol_m if self.split_tol_m > 0 else max(0.05, 4.0 * self.range_sigma_m)


@dataclass
class PoseDiagnostics:
    """What extraction found for one pose. ``used`` is True when the pose became a board of the Observations
    (``board_index`` then says which); otherwise ``reason`` says why it was skipped."""

    name: str
    used: bool = False
    reason: str | None = None
    board_index: int | None = None
    n_corners: int = 0
    reproj_rms_px: float = math.nan
    cam_distance_m: float = math.nan
    n_scan: int = 0
    n_background: int = 0
    n_segments: int = 0
    n_candidates: int = 0
    source: str = ""
    segment: tuple[int, int] | None = None
    ambiguous: list[tuple[int, int]] = field(default_factory=list)
    n_points: int = 0
    bearing_deg: tuple[float, float] | None = None
    length_m: float = math.nan
    range_m: float = math.nan
    line_rms_mm: float = math.nan
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}
