"""Likely causes of an answer the data contradict (see ``calib_core.checks.verdict``): each returns (name, message).

- ``units``: scan coordinates, board positions or outlines about 1000x too large (millimetres written as metres),
  judged from the data alone (ranges, board distances and sizes against each other and against plausible rigs);
- ``mispaired``: the scans fit every board once they are re-paired with the boards (a permutation: two swapped,
  all shifted by one, ...): candidates of the minimal solver on board triples paired with scan triples, for each
  candidate the pairing of scans with board planes of least cost (Hungarian assignment, scipy), the best one
  refined and re-tested. (Mirrored scans, ``y -> -y``, fit an upside-down lidar exactly: no contradiction, see
  ``verdict.orientation_warnings``.)
- ``scale``: the board poses fit the scans only once their translations are scaled: an error of the camera
  intrinsics (focal length) or of the board's square size.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import linear_sum_assignment, minimize_scalar

from ..data.lines import scan_lines, triple_inputs
from ..data.observations import MIN_RANGE_M, BoardObservation, Observations
from ..errors import SolveFailure
from ..model.residuals import range_residuals
from ..refine.refine import refine
from .verdict import (
    CLIP_Z,
    MIN_DEPTH_M,
    Verdict,
    check,
    effective_sigma,
    is_consistent,
    measured_points,
    unit_causes,
)

MAX_DIAGNOSE_BOARDS = 12
"""Above this many boards the pairing hypotheses are not tried (their cost grows as N^4)."""
PAIR_COST_SIGMAS = 5.0
"""A scan's cost against a board plane: its median |range residual| in units of this many noise stds ..."""
PAIR_COST_CAP = 10.0
"""... capped here (a scan far off a plane costs the same however far)."""
MAX_PAIRING_WORK = 5e7
"""The pairing is not tried when candidates x boards x scan points exceed this (memory and time)."""
DIAGNOSE_F_SCALE_SIGMAS = 3.0
"""Scale (noise stds) of the robust loss of the diagnoses' refinements."""
SCALE_RANGE = (0.7, 1.4)
"""The board-pose scale factors searched (``scale_causes``) ..."""
SCALE_XATOL = 0.005
"""... to this tolerance in log-scale ..."""
SCALE_MAXITER = 14
"""... in at most this many steps, each a refinement of at most ``SCALE_MAX_NFEV`` evaluations ..."""
SCALE_MAX_NFEV = 15
MIN_SCALE_CHANGE = 0.02
"""... and a scale within this of 1 is no cause."""


def _rebuilt(obs: Observations, scans, trans_scale: float = 1.0) -> Observations:
    boards = []
    for b, s in zip(obs.boards, scans, strict=True):
        T = np.array(b.T_cam_board)
        T[:3, 3] *= trans_scale
        boards.append(BoardObservation(T, b.outline, s, outline_kind=b.outline_kind))
    return Observations(tuple(boards), obs.T_lidar_cam_true, dict(obs.meta))


def _pair_costs(obs: Observations, C: np.ndarray, sigma: float) -> np.ndarray:
    """(M,S,P): median |range residual| / (``PAIR_COST_SIGMAS`` sigma), capped at ``PAIR_COST_CAP``, of scan S
    against board plane P per candidate."""
    n, d = obs.planes_cam()
    m = np.einsum("mab,pb->mpa", C[:, :3, :3], n)                             # (M,P,3) normals, lidar frame
    c = d + np.einsum("mpa,ma->mp", m, C[:, :3, 3])                            # (M,P)
    out = np.empty((len(C), obs.n_boards, obs.n_boards))
    for s, b in enumerate(obs.boards):
        r = np.linalg.norm(b.scan, axis=1)
        keep = r > MIN_RANGE_M
        beams = b.scan[keep] / r[keep, None]
        mb = np.einsum("mpa,ka->mpk", m[..., :2], beams)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.abs(r[keep] - c[..., None] / mb)
        out[:, s, :] = np.nan_to_num(np.median(e, axis=-1), nan=np.inf) if keep.any() else np.inf
    return np.minimum(out / (PAIR_COST_SIGMAS * sigma), PAIR_COST_CAP)


EXHAUSTIVE_PAIRING_BOARDS = 6
"""Up to this many boards every pairing of scan triples with board triples is solved (N! / (N-3)! x C(N,3)
minimal problems), so any permutation of the scans is found; above it, only triples paired as given."""


def _candidates(obs: Observations, exhaustive: bool) -> np.ndarray:
    """Minimal-solver candidates (M,4,4) from board triples paired with scan triples (as given, or every ordered
    triple of scans when ``exhaustive``)."""
    from itertools import permutations

    from ..solvers._common import board_triples
    from ..solvers.vasconcelos import solve_triples

    scan_lines(obs).require_line_like()
    tri = board_triples(obs.n_boards)
    if exhaustive:
        scans = np.array([q for t in tri for q in permutations(t)])
        P, Q = np.repeat(tri, len(scans), axis=0), np.tile(scans, (len(tri), 1))
        keep = np.array([len(set(a) | set(b)) >= 3 for a, b in zip(P, Q, strict=True)])
        P, Q = P[keep], Q[keep]
    else:
        P = Q = tri
    return solve_triples(*triple_inputs(obs, P, Q)).T_lidar_cam


def best_pairing(obs: Observations, sigma: float, exhaustive: bool = False):
    """(cost, permutation, T, re-paired observations) of the least-cost pairing of scans with boards over the
    minimal-solver candidates, or None: ``permutation[p]`` is the scan that belongs to board ``p``; ``T`` refined
    on the re-paired data."""
    try:
        C = _candidates(obs, exhaustive)
    except SolveFailure:
        return None
    if not len(C) or len(C) * obs.n_boards * sum(len(b.scan) for b in obs.boards) > MAX_PAIRING_WORK:
        return None
    costs = _pair_costs(obs, C, sigma)
    best = None
    for j in range(len(C)):
        rows, cols = linear_sum_assignment(costs[j].T)          # rows: planes, cols: scans
        total = float(costs[j].T[rows, cols].sum())
        if best is None or total < best[0]:
            best = (total, cols, C[j])
    total, perm, T0 = best
    paired = _rebuilt(obs, [obs.boards[k].scan for k in perm])
    try:
        T = refine(paired.scan_data, T0, residual="range", loss="soft_l1",
                   f_scale_m=DIAGNOSE_F_SCALE_SIGMAS * sigma).T_lidar_cam
    except Exception:  # noqa: BLE001 -- a diagnosis never fails the answer
        return None
    return total, perm, T, paired


def _shift_text(perm: np.ndarray) -> str:
    N = len(perm)
    for k in range(1, N):
        if np.array_equal(perm, np.roll(np.arange(N), -k)):
            k = k if k <= N // 2 else k - N
            return (f"images and scans shifted by {abs(k)} pose(s): every board fits the scan given for the board "
                    f"{abs(k)} {'after' if k > 0 else 'before'} it")
    moved = [(p, int(s)) for p, s in enumerate(perm) if p != s]
    return "mispaired scans: " + ", ".join(f"board {p} fits the scan given for board {s}" for p, s in moved[:6])


def pairing_causes(obs: Observations, sigma: float) -> list[tuple[str, str]]:
    """Mispaired scans, when a re-pairing fits every board: any permutation up to ``EXHAUSTIVE_PAIRING_BOARDS``
    boards; above, re-pairings found from correctly paired triples, and every cyclic shift."""
    N = obs.n_boards
    if not 4 <= N <= MAX_DIAGNOSE_BOARDS:
        return []
    exhaustive = N <= EXHAUSTIVE_PAIRING_BOARDS
    shifts = [np.arange(N)] + ([] if exhaustive else [np.roll(np.arange(N), -k) for k in range(1, N)])
    for shift in shifts:
        found = best_pairing(_rebuilt(obs, [obs.boards[k].scan for k in shift]), sigma, exhaustive)
        if found is None:
            continue
        _, perm, T, paired = found
        perm = shift[perm]
        if not np.array_equal(perm, np.arange(N)) and is_consistent(paired, T, sigma):
            return [("mispaired", _shift_text(perm))]
    return []


def scale_causes(obs: Observations, T: np.ndarray, sigma: float) -> list[tuple[str, str]]:
    """Board poses that fit only once their translations are scaled by s in ``SCALE_RANGE`` (intrinsics or square size
    off): a bounded 1D search (scipy) of the clipped chi-square of the range residuals, refined from ``T``."""
    def fit(log_s):
        o = _rebuilt(obs, [b.scan for b in obs.boards], float(np.exp(log_s)))
        Ts = refine(o.scan_data, T, residual="range", loss="soft_l1", f_scale_m=DIAGNOSE_F_SCALE_SIGMAS * sigma,
                    max_nfev=SCALE_MAX_NFEV).T_lidar_cam
        z = range_residuals(Ts, measured_points(o)) / sigma
        return float(np.sum(np.minimum(z**2, CLIP_Z**2))), Ts, o

    sol = minimize_scalar(lambda x: fit(x)[0], bounds=tuple(np.log(SCALE_RANGE)), method="bounded",
                          options={"xatol": SCALE_XATOL, "maxiter": SCALE_MAXITER})
    s = float(np.exp(sol.x))
    _, Ts, o = fit(sol.x)
    if abs(s - 1) < MIN_SCALE_CHANGE or not is_consistent(o, Ts, sigma):
        return []
    return [("scale", f"the board poses fit the scans only once their distances are scaled by {s:.3f}: the camera "
                      f"intrinsics (focal length) or the board's square size are off by about {100 * (s - 1):+.0f}%")]


def explain_contradiction(obs: Observations, T: np.ndarray, sigma: float) -> list[tuple[str, str]]:
    """The likely causes of a contradicted answer, most specific first (empty when none is found)."""
    causes = unit_causes(obs)
    if causes:
        return causes
    try:
        causes = pairing_causes(obs, sigma)
        if not causes and 4 <= obs.n_boards <= MAX_DIAGNOSE_BOARDS:
            causes = scale_causes(obs, T, sigma)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):  # a diagnosis never fails the answer
        return []
    return causes


def judge(obs: Observations, T: np.ndarray, *, range_sigma_m: float | None = None, board_ids=None) -> Verdict:
    """``verdict.check`` of ``T``, with the likely causes of a contradiction added (``explain_contradiction``;
    skipped when a board is out of the camera's view: that explains itself)."""
    v = check(obs, T, range_sigma_m=range_sigma_m, board_ids=board_ids)
    if v.consistent or min(s["depth_m"] for s in v.boards) < MIN_DEPTH_M:
        return v
    causes = explain_contradiction(obs, T, v.sigma_m)
    warnings = list(v.warnings) + [f"likely cause: {msg}" for _, msg in causes if msg not in v.warnings]
    return replace(v, warnings=tuple(warnings), causes=tuple(dict.fromkeys([*v.causes, *(n for n, _ in causes)])))


def data_causes(obs: Observations) -> list[tuple[str, str]]:
    """Likely causes visible without an answer: units, or mispaired scans (``pairing_causes``)."""
    return unit_causes(obs) or pairing_causes(obs, effective_sigma(obs))
