"""The data model: one board view (camera pose of the board + lidar scan on it) and a set of them.

Frames (see docs/METHOD.md): ``{L}`` lidar, scan plane z = 0; ``{C}`` camera (z optical axis, y down);
``{W}_i`` board i, board plane z = 0. Units: metres, radians. ``T_a_b`` maps points of b into a.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property
from typing import Any

import numpy as np

from ..errors import ObservationError
from ..geometry.polygon import check_simple_polygon
from ..geometry.transforms import ROTATION_TOL, project_to_so3, rotation_defect
from .camera import CameraModel

MIN_SCAN_POINTS = 2
MIN_RANGE_M = 1e-3
"""Scan points closer than this to the lidar (metres) are not measurements (a no-return is often written 0)."""
MIN_CORNERS = 4
"""Fewest image corners a board may carry (a planar pose needs 4)."""
MAX_DISTANCE_M = 1e6
"""Farthest a scan point or a board may lie from its sensor (metres): far beyond a unit mistake (millimetres read as
metres stay below it, and the verdict names those), so only a garbage value (1e300) is refused when loaded."""


class OutlineKind(StrEnum):
    """What a board's ``outline`` says of the physical board: ``exact`` (the edges the lidar meets; the default;
    evidence for the endpoint and outline terms and tests), ``lower_bound`` (inside the physical board, e.g. a
    printed pattern on a larger board: evidence for ``refine.lower_bound``'s one-sided terms) or ``none``."""

    EXACT, LOWER_BOUND, NONE = "exact", "lower_bound", "none"


OUTLINE_KINDS = tuple(k.value for k in OutlineKind)  # as the observation file writes them

MAX_BOARDS = 100
"""Most boards one problem may hold (the exhaustive methods grow as N^4); more are refused when loaded."""
MAX_SCAN_POINTS = 20_000
"""Most scan points on one board (a 2D lidar sweep has a few thousand beams)."""
MAX_OUTLINE_VERTICES = 64
"""Most vertices of one board outline."""
LOAD_ROTATION_TOL = 1e-5
"""Largest ``|R^T R - I|`` of a rotation read from a file: 6 written decimals give about 1e-6; such a rotation is
re-orthonormalised (``orthonormalised``) with a note."""


def _bad_leaf(value, depth: int) -> str | None:
    """Why nested lists ``value`` (at most ``depth`` levels) are not all numbers (bool is not a number), or None."""
    stack = [(value, depth, "")]
    while stack:
        v, d, where = stack.pop()
        if isinstance(v, (list, tuple)):
            if d == 0:
                return f"nested deeper than expected at {where or 'top'}"
            stack.extend((x, d - 1, f"{where}[{i}]") for i, x in enumerate(v))
        elif isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            return f"not a number at {where or 'top'} ({type(v).__name__} {str(v)[:20]!r})"
    return None


def numeric_array(value, name: str, shape: tuple, max_len: int | None = None) -> np.ndarray:
    """Float copy of ``value`` (nested lists of numbers, or a numeric ndarray), checked against ``shape`` (None =
    any length, at most ``max_len``) and for finiteness, read-only; ObservationError naming ``name`` otherwise.
    Booleans and strings are not numbers."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "fiu":
            raise ObservationError(f"not a numeric array (dtype {value.dtype})", field=name)
    else:
        if max_len is not None and isinstance(value, (list, tuple)) and len(value) > max_len:
            raise ObservationError(f"{len(value)} entries, more than the limit of {max_len}", field=name)
        why = _bad_leaf(value, len(shape))
        if why:
            raise ObservationError(why, field=name)
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ObservationError(f"not a numeric array ({exc})", field=name) from None
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True)):
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise ObservationError(f"expected shape {want}, got {'x'.join(map(str, a.shape)) or 'scalar'}",
                               field=name)
    if max_len is not None and len(a) > max_len:
        raise ObservationError(f"{len(a)} entries, more than the limit of {max_len}", field=name)
    if not np.all(np.isfinite(a)):
        raise ObservationError("contains NaN or inf", field=name)
    a.setflags(write=False)
    return a


_frozen_array = numeric_array


def orthonormalised(T, name: str) -> tuple[np.ndarray, str | None]:
    """A 4x4 transform read from a file, its rotation projected onto SO(3) when within ``LOAD_ROTATION_TOL`` of
    it (written with few decimals), and the note saying so (None when untouched or too far: the data model
    then refuses it)."""
    A = np.array(numeric_array(T, name, (4, 4)))
    defect = rotation_defect(A[:3, :3])
    if ROTATION_TOL < defect <= LOAD_ROTATION_TOL:
        A[:3, :3] = project_to_so3(A[:3, :3])
        return A, f"'{name}': rotation re-orthonormalised (|R^T R - I| was {defect:.1e})"
    return A, None


def check_outline_kind(kind) -> str:
    """``kind`` when it is one of ``OUTLINE_KINDS``; ObservationError naming the field otherwise."""
    if not isinstance(kind, str) or kind not in OUTLINE_KINDS:
        raise ObservationError(f"must be one of {', '.join(map(repr, OUTLINE_KINDS))}, got {str(kind)[:40]!r}",
                               field="outline_kind")
    return kind


@dataclass(frozen=True, eq=False)
class BoardObservation:
    """One view of a planar calibration board by both sensors.

    Attributes:
        T_cam_board: 4x4 pose of the board in the camera, maps board-frame points (board plane z = 0)
            into the camera frame; metres.
        outline: (V,2) ordered vertices of the board's physical outline in its own frame (z = 0), metres.
            The paper's square of side c is ``[[0,0],[c,0],[c,c],[0,c]]``. None only when ``outline_kind`` is
            ``none``.
        scan: (K,2) lidar points on this board, in the lidar frame (scan plane z = 0), ordered by bearing;
            metres.
        corners_px: optional (J,2) detected image corners, distorted pixels as the detector returns them.
        corners_board: optional (J,3) the same corners in the board frame (metres; given as (J,2) on z = 0).
            Both or neither; they need the file's ``Observations.camera``.
        outline_kind: ``exact`` (default), ``lower_bound`` or ``none`` (``OUTLINE_KINDS``): how far ``outline``
            is the edge the lidar meets.
    """

    T_cam_board: np.ndarray
    outline: np.ndarray | None
    scan: np.ndarray
    corners_px: np.ndarray | None = None
    corners_board: np.ndarray | None = None
    outline_kind: str = "exact"

    def __post_init__(self) -> None:
        T = _frozen_array(self.T_cam_board, "T_cam_board", (4, 4))
        if not np.allclose(T[3], [0, 0, 0, 1], atol=ROTATION_TOL):
            raise ObservationError("last row must be [0, 0, 0, 1]", field="T_cam_board")
        defect = rotation_defect(T[:3, :3])
        if defect > ROTATION_TOL:
            what = "is a reflection or singular" if not np.isfinite(defect) else \
                f"is not orthonormal (|R^T R - I| = {defect:.2g} > {ROTATION_TOL:g})"
            raise ObservationError(f"rotation {what}", field="T_cam_board")
        if np.abs(T[:3, 3]).max() > MAX_DISTANCE_M:
            raise ObservationError(f"translation {np.abs(T[:3, 3]).max():.3g} m, beyond {MAX_DISTANCE_M:g} m",
                                   field="T_cam_board")
        check_outline_kind(self.outline_kind)
        outline = None if self.outline is None and self.outline_kind == "none" else self._checked_outline()
        scan = numeric_array(self.scan, "scan", (None, 2), MAX_SCAN_POINTS)
        at_origin = np.flatnonzero(np.hypot(scan[:, 0], scan[:, 1]) < MIN_RANGE_M)
        if len(at_origin):
            raise ObservationError(f"scan point {at_origin[0]} is at the lidar origin (range < {MIN_RANGE_M * 1000:g} "
                                   "mm: a no-return, not a measurement; leave it out)", field="scan")
        if len(scan) < MIN_SCAN_POINTS:
            raise ObservationError(f"fewer than {MIN_SCAN_POINTS} scan points ({len(scan)})", field="scan")
        if len(far := np.flatnonzero(np.abs(scan).max(axis=1) > MAX_DISTANCE_M)):
            raise ObservationError(f"scan point {far[0]} lies beyond {MAX_DISTANCE_M:g} m", field="scan")
        object.__setattr__(self, "T_cam_board", T)
        object.__setattr__(self, "outline", outline)
        object.__setattr__(self, "scan", scan)
        self._check_corners()

    def _checked_outline(self) -> np.ndarray:
        if self.outline is None:
            raise ObservationError("missing (only a board with outline_kind 'none' may omit it)", field="outline")
        outline = numeric_array(self.outline, "outline", (None, 2), MAX_OUTLINE_VERTICES + 1)
        if len(outline) >= 4 and np.array_equal(outline[0], outline[-1]):
            outline = outline[:-1]  # a closed ring: the first vertex repeated at the end
        if len(outline) > MAX_OUTLINE_VERTICES:
            raise ObservationError(f"{len(outline)} vertices, more than the limit of {MAX_OUTLINE_VERTICES}",
                                   field="outline")
        why = check_simple_polygon(outline)
        if why:
            raise ObservationError(f"outline {why}", field="outline")
        return outline

    @property
    def outline_exact(self) -> bool:
        """True when the outline is the edge the lidar meets (``outline_kind`` ``exact``): only then are the scan
        ends and points evidence against it."""
        return self.outline_kind == "exact"

    def _check_corners(self) -> None:
        if self.corners_px is None and self.corners_board is None:
            return
        for name in ("corners_px", "corners_board"):
            if getattr(self, name) is None:
                other = "corners_board" if name == "corners_px" else "corners_px"
                raise ObservationError(f"missing while {other} is given (both or neither)", field=name)
        px = _frozen_array(self.corners_px, "corners_px", (None, 2))
        planar = np.ndim(self.corners_board) == 2 and np.shape(self.corners_board)[1] == 2
        pb = _frozen_array(self.corners_board, "corners_board", (None, 2 if planar else 3))
        if planar:
            pb = np.column_stack([pb, np.zeros(len(pb))])
            pb.setflags(write=False)
        if len(px) != len(pb):
            raise ObservationError(f"{len(px)} image corners but {len(pb)} board corners", field="corners_board")
        if len(px) < MIN_CORNERS:
            raise ObservationError(f"fewer than {MIN_CORNERS} corners ({len(px)})", field="corners_px")
        object.__setattr__(self, "corners_px", px)
        object.__setattr__(self, "corners_board", pb)

    @property
    def has_corners(self) -> bool:
        return self.corners_px is not None

    @property
    def centre(self) -> np.ndarray:
        """(2,) a point of the board in its own frame (metres): the outline's vertex mean, else the corners',
        else the board origin."""
        if self.outline is not None:
            return self.outline.mean(axis=0)
        return self.corners_board[:, :2].mean(axis=0) if self.has_corners else np.zeros(2)

    @property
    def normal_cam(self) -> np.ndarray:
        """Unit normal ``n = Phi e3`` of the board plane in the camera frame."""
        return self.T_cam_board[:3, 2]

    @property
    def offset_cam(self) -> float:
        """Plane offset ``d = n . Delta`` (metres): the plane is ``{p_C : n . p_C = d}``."""
        return float(self.normal_cam @ self.T_cam_board[:3, 3])

    @cached_property
    def scan_3d(self) -> np.ndarray:
        """(K,3) scan points in the lidar frame with z = 0 (built once, read-only)."""
        p = np.column_stack([self.scan, np.zeros(len(self.scan))])
        p.setflags(write=False)
        return p


@dataclass(frozen=True, eq=False)
class ScanData:
    """All scan points of a problem, flattened, with the plane of the board each lies on.

    Attributes:
        points: (K,3) lidar-frame points, z = 0 (metres).
        board: (K,) board index of each point.
        normals: (N,3) board unit normals in the camera frame; offsets: (N,) plane offsets (metres).
    """

    points: np.ndarray
    board: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray

    def of_boards(self, boards: np.ndarray) -> ScanData:
        """The points of the boards where ``boards`` (N,) bool is True, renumbered in order: the ``scan_data`` of
        ``Observations.subset(np.flatnonzero(boards))``, taken from this one (ranges and beams carried over)."""
        keep, renumber = boards[self.board], np.cumsum(boards) - 1
        out = ScanData(self.points[keep], renumber[self.board[keep]], self.normals[boards], self.offsets[boards])
        for name in ("ranges", "beams"):
            if name in self.__dict__:
                out.__dict__[name] = self.__dict__[name][keep]
        return out

    @cached_property
    def ranges(self) -> np.ndarray:
        """(K,) measured range ``|p|`` of every point (metres)."""
        return np.linalg.norm(self.points, axis=1)

    @cached_property
    def beams(self) -> np.ndarray:
        """(K,3) unit beam direction ``p / |p|`` of every point."""
        return self.points / self.ranges[:, None]

    @classmethod
    def from_observations(cls, obs: Observations) -> ScanData:
        """Flatten the scans of ``obs`` (use ``obs.scan_data``: built once per Observations)."""
        pts = np.concatenate([b.scan_3d for b in obs.boards])
        idx = np.concatenate([np.full(len(b.scan), i) for i, b in enumerate(obs.boards)])
        n, d = obs.planes_cam()
        return cls(pts, idx, n, d)


@dataclass(frozen=True, eq=False)
class Observations:
    """The boards of one calibration problem, with optional ground truth.

    Attributes:
        boards: the board views.
        T_lidar_cam_true: optional 4x4 true extrinsic (maps camera points into the lidar frame;
            the paper's ``p_L = R p_C + t``).
        meta: free-form provenance (simulator settings, seed, source file); not used by the solvers.
        camera: optional camera model (``calib_core.data.cameras``); required when a board carries corners.
    """

    boards: tuple[BoardObservation, ...]
    T_lidar_cam_true: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    camera: CameraModel | None = None

    def __post_init__(self) -> None:
        boards = tuple(self.boards)
        if len(boards) > MAX_BOARDS:
            raise ObservationError(f"{len(boards)} boards, more than the limit of {MAX_BOARDS}", field="boards")
        for i, b in enumerate(boards):
            if not isinstance(b, BoardObservation):
                raise ObservationError(f"not a BoardObservation ({type(b).__name__})", board=i)
            if b.has_corners and self.camera is None:
                raise ObservationError("image corners given but the file has no camera intrinsics", board=i,
                                       field="camera")
        if self.camera is not None and not isinstance(self.camera, CameraModel):
            raise ObservationError(f"not a camera model ({type(self.camera).__name__})", field="camera")
        object.__setattr__(self, "boards", boards)
        if self.T_lidar_cam_true is not None:
            T = _frozen_array(self.T_lidar_cam_true, "ground_truth.T_lidar_cam", (4, 4))
            if rotation_defect(T[:3, :3]) > ROTATION_TOL or not np.allclose(T[3], [0, 0, 0, 1]):
                raise ObservationError("not a rigid transform", field="ground_truth.T_lidar_cam")
            object.__setattr__(self, "T_lidar_cam_true", T)

    def __len__(self) -> int:
        return len(self.boards)

    @property
    def n_boards(self) -> int:
        return len(self.boards)

    def subset(self, indices) -> Observations:
        """The same problem with only the boards at ``indices`` (in that order; ``self`` for all in order). Per-board
        derived values (with a ``subset_boards`` method, e.g. the scan lines) are carried over, not recomputed."""
        if (indices := [int(i) for i in indices]) == list(range(self.n_boards)):
            return self
        # every part was validated when ``self`` was built: the subset is assembled, not validated again
        out = object.__new__(Observations)
        out.__dict__.update(boards=tuple(self.boards[i] for i in indices), T_lidar_cam_true=self.T_lidar_cam_true,
                            meta=dict(self.meta), camera=self.camera)
        per_board = {k: v.subset_boards(indices) for k, v in self.__dict__.get("_derived", {}).items()
                     if hasattr(v, "subset_boards")}
        if per_board:
            out.__dict__["_derived"] = per_board
        return out

    @property
    def has_corners(self) -> bool:
        """True when every board carries image corners (and the camera is known): the joint model applies."""
        return bool(self.boards) and self.camera is not None and all(b.has_corners for b in self.boards)

    @property
    def exact_outlines(self) -> np.ndarray:
        """(N,) bool: boards whose outline is exact (``BoardObservation.outline_exact``)."""
        return np.array([b.outline_exact for b in self.boards], dtype=bool)

    def planes_cam(self) -> tuple[np.ndarray, np.ndarray]:
        """Board planes in the camera frame: normals (N,3) and offsets (N,), plane ``n . p_C = d`` (built once,
        read-only)."""
        return self.derived("observations.planes_cam", _planes_cam)

    def derived(self, key: str, fn):
        """``fn(self)``, computed once per ``Observations`` and kept under ``key`` (data derived from the boards
        alone, such as a noise estimate, that several steps read)."""
        cache = self.__dict__.setdefault("_derived", {})
        if key not in cache:
            cache[key] = fn(self)
        return cache[key]

    @cached_property
    def scan_data(self) -> ScanData:
        """All scan points flattened with their boards' planes (built once)."""
        return ScanData.from_observations(self)


def _planes_cam(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    n = np.array([b.normal_cam for b in obs.boards], float).reshape(-1, 3)
    d = np.array([b.offset_cam for b in obs.boards], float)
    n.setflags(write=False), d.setflags(write=False)
    return n, d
