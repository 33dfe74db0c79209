"""Per-board systematic range error: what moves a whole board as the lidar sees it, beyond the per-beam noise.

Three terms, all off by default (``SimOptions``), drawn from their own random stream (``surface_rng``) so that they
never shift the geometry, noise, margin or intrinsics streams:

- ``lidar_board_offset_mm``: a range offset shared by every beam on one board (a surface's finish and the incidence
  angle bias a Hokuyo's range), drawn per board from N(0, ``lidar_board_offset_mm``) and added along each beam.
- ``lidar_dark_offset_mm``: the range difference between a checkerboard's dark and light squares (a Hokuyo reads
  them centimetres apart): a beam hitting a dark square reads ``+d/2``, a light one (or the board's plain margin)
  ``-d/2``; the return's intensity is the square's reflectance (``DARK_INTENSITY``, ``LIGHT_INTENSITY``).
- ``board_bow_mm``: a board that is not flat: its surface bulges along its normal by ``a (1 - rho^2)``, rho the
  distance from the outline's centre over the half-diagonal (0 at the corners, ``a`` at the centre), ``a`` drawn per
  board from N(0, ``board_bow_mm``) (positive: towards the sensors); first order in ``a`` (mm bows on a metre board).

Frames: ``{L}`` lidar (scan plane z = 0); ``{W}`` board (plane z = 0, z away from the sensors). Units: metres.
"""

from __future__ import annotations

import numpy as np

from .camera import BoardSpec
from .options import SimOptions

SURFACE_STREAM = 5
"""Child index of a trial's ``SeedSequence`` of the systematic-error stream (0-2 geometry/noise, 3-4 rig)."""
DARK_INTENSITY, LIGHT_INTENSITY = 0.1, 0.9
"""Reflectance of a dark and a light square (the intensity a return from them would have, 0-1)."""


def systematic_on(options: SimOptions) -> bool:
    """True when some per-board systematic range error is simulated."""
    return (options.lidar_board_offset_mm > 0 or options.lidar_dark_offset_mm != 0
            or options.board_bow_mm > 0)


def board_range_sigma_m(options: SimOptions) -> float:
    """The per-board systematic scale the file states (metres): the 1-sigma of the range offset shared by one
    board's beams (``lidar_board_offset_mm``). The square colours and the bow are not summarised in it: they vary
    along a board, and the options (``meta["options"]``) state them."""
    return options.lidar_board_offset_mm / 1000.0


def surface_rng(options: SimOptions, seed: int, trial: int, stream: int | None = None) -> np.random.Generator:
    """The systematic-error generator of one trial: child ``SURFACE_STREAM`` of the trial's ``SeedSequence``."""
    from . import trial_key

    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(trial_key(options, stream), int(trial)))
    return np.random.default_rng(ss.spawn(SURFACE_STREAM + 1)[SURFACE_STREAM])


def draw_systematic(options: SimOptions, rng: np.random.Generator, n_boards: int) -> tuple[np.ndarray, np.ndarray]:
    """Per board (range offset (n,), bow amplitude (n,)) in metres, drawn in that order."""
    offset = rng.normal(0.0, 1.0, n_boards) * options.lidar_board_offset_mm / 1000.0
    bow = rng.normal(0.0, 1.0, n_boards) * options.board_bow_mm / 1000.0
    return offset, bow


def hits_on_board(points: np.ndarray, T_lidar_board: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the beams through ``points`` (K,2) in ``{L}`` meet the flat board: (board xy (K,2), range (K,),
    cos of the incidence angle (K,), > 0)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    r = np.linalg.norm(pts, axis=1)
    u = np.column_stack([pts / np.where(r > 0, r, 1.0)[:, None], np.zeros(len(pts))])
    R, t = T_lidar_board[:3, :3], T_lidar_board[:3, 3]
    n = R[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        r_flat = (n @ t) / (u @ n)
    X = (r_flat[:, None] * u - t) @ R
    return X[:, :2], r_flat, np.abs(u @ n)


def dark_square(xy: np.ndarray, spec: BoardSpec) -> np.ndarray:
    """True where board-frame points ``xy`` (K,2) lie on a dark square of the pattern (as ``board_texture`` colours
    it); the margin beyond the pattern is light."""
    ox, oy = spec.pattern_origin
    ix = np.floor((xy[:, 0] - ox) / spec.square_m).astype(int)
    iy = np.floor((xy[:, 1] - oy) / spec.square_m).astype(int)
    inside = (ix >= 0) & (ix < spec.squares_x) & (iy >= 0) & (iy < spec.squares_y)
    return inside & ((ix + iy) % 2 == 1)


def range_errors(options: SimOptions, points: np.ndarray, T_lidar_board: np.ndarray, outline: np.ndarray,
                 offset_m: float, bow_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The systematic range error (K,) (metres, along each beam) of the returns ``points`` (K,2) from one board
    with pose ``T_lidar_board`` and physical ``outline`` (V,2), and each return's intensity (K,)."""
    xy, _, cos_inc = hits_on_board(points, T_lidar_board)
    dark = dark_square(xy, BoardSpec.of(options))
    d = options.lidar_dark_offset_mm / 1000.0
    outline = np.asarray(outline, float)
    centre = 0.5 * (outline.min(axis=0) + outline.max(axis=0))
    half_diag2 = np.max(np.sum((outline - centre) ** 2, axis=1))
    rho2 = np.sum((xy - centre) ** 2, axis=1) / half_diag2
    bulge = bow_m * (1.0 - rho2)                      # towards the sensors: the beam meets it sooner
    err = offset_m + np.where(dark, d / 2, -d / 2) - bulge / np.maximum(cos_inc, 1e-3)
    return err, np.where(dark, DARK_INTENSITY, LIGHT_INTENSITY)


def apply_systematic(options: SimOptions, scans: list[np.ndarray], T_lidar_board: np.ndarray, outlines: list,
                     rng: np.random.Generator) -> tuple[list[np.ndarray], dict]:
    """``scans`` (per board (K_i,2) in ``{L}``) with each board's systematic range error added along its beams, and
    what was drawn (``board_range_offset_m``, ``board_bow_m`` per board) for the file's ``meta``."""
    offset, bow = draw_systematic(options, rng, len(scans))
    out = []
    for s, T, ol, o_m, b_m in zip(scans, T_lidar_board, outlines, offset, bow, strict=True):
        s = np.asarray(s, float)
        if len(s) == 0:
            out.append(s)
            continue
        err, _ = range_errors(options, s, T, ol, float(o_m), float(b_m))
        r = np.linalg.norm(s, axis=1)
        out.append(s * ((r + err) / r)[:, None])
    return out, {"board_range_offset_m": offset.tolist(), "board_bow_m": bow.tolist()}
