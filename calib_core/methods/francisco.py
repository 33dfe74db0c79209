"""Francisco's method as its authors ran it, and the second minimal solver (Zhou 2014).

The paper's ``vasconcelos`` (``methods/baselines.py``) follows the paper's description: every candidate of all
board triples, the one of least point-to-plane error.  The authors' MATLAB (``lccMinSol`` /
``laserCamMSACCalib`` / ``LaserCamCalibError`` / ``optimizeLaserCamCalib``, as copied in the public
``jbriales/corner-calib`` at its first commit) selects differently; ``vasconcelos_msac`` reproduces that
selection and ``vasconcelos_msac_refined`` its default output.  ``zhou2014`` is Zhou's algebra
(``calib_core/solvers/zhou2014.py``) with point-to-plane selection.
"""

from __future__ import annotations

import numpy as np

from ..data.lines import scan_lines
from ..data.observations import Observations
from ..errors import SolveFailure
from ..refine.refine import MAX_NFEV, refine
from ..registry import Method
from ..solvers._common import MIN_BOARDS
from ..solvers.candidates import minimal_candidates, solver_keywords
from .baselines import EXHAUSTIVE, VASC_CITE, select_candidate

ZHOU_CITE = "L. Zhou, IEEE Sensors Journal 14(2) 2014"

MSAC_THRESHOLD_PER_MM = 1e-5
"""The authors' MSAC inlier threshold on the dual-space error (``rt = 0.00001``, the code's recommended default).
The error is a distance between plane coordinates normalised by their 4th entry, so its unit is 1/mm."""

MSAC_SCAN_PLANE_Z_MM = 10.0
"""The authors' code places the scan plane at z = 10 mm of its laser frame ("z=0 is problematic": a plane
through the origin has no normalised coordinates); the dual-space error is measured in that frame."""


def msac_errors(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """The authors' per-board error (M,N) of candidates (M,4,4) ``T_lidar_cam``, in 1/mm.

    Frame and units as in their code: millimetres, the scan plane at ``z = MSAC_SCAN_PLANE_Z_MM`` (the candidate's
    translation moved up by that much).  Board i's camera plane ``n . p = d`` is written ``a_C . p + 1 = 0`` with
    ``a_C = -n / d``; moved into the laser frame it is ``a_L = R a_C / (1 - t . R a_C)``.  The board's scan line,
    through ``p0 = (x, y, z0)`` with direction ``u = (ux, uy, 0)``, is in the dual space the line of planes
    ``{a : a . p0 + 1 = 0, a . u = 0}``; the error is the Euclidean distance from ``a_L`` to it,
    ``sqrt(r^T (A A^T)^-1 r)`` with ``A = [p0; u]`` and ``r = A a_L - (-1, 0)``.  Scan lines are the total
    least-squares lines, which the code's Plucker line fit equals (its centred problem is block diagonal).
    """
    n, d = obs.planes_cam()
    a_c = -n / (1e3 * d)[:, None]                                              # (N,3) 1/mm
    lines = scan_lines(obs)
    p0 = np.column_stack([1e3 * lines.centroid, np.full(obs.n_boards, MSAC_SCAN_PLANE_Z_MM)])  # (N,3) mm
    u = np.column_stack([lines.direction, np.zeros(obs.n_boards)])           # (N,3)
    C = np.asarray(candidates, float).reshape(-1, 4, 4)
    t = 1e3 * C[:, :3, 3] + np.array([0.0, 0.0, MSAC_SCAN_PLANE_Z_MM])       # (M,3) mm
    Ra = np.einsum("mij,nj->mni", C[:, :3, :3], a_c)                           # (M,N,3)
    with np.errstate(divide="ignore", invalid="ignore"):
        a_l = Ra / (1.0 - np.einsum("mni,mi->mn", Ra, t))[..., None]
    r = np.stack([np.einsum("mni,ni->mn", a_l, p0) + 1.0, np.einsum("mni,ni->mn", a_l, u)], axis=-1)
    A = np.stack([p0, u], axis=1)                                              # (N,2,3)
    G = np.linalg.inv(A @ np.swapaxes(A, 1, 2))                                # (N,2,2)
    return np.sqrt(np.maximum(np.einsum("mna,nab,mnb->mn", r, G, r), 0.0))


def msac_select(obs: Observations, cands, threshold: float = MSAC_THRESHOLD_PER_MM):
    """The authors' MSAC over every candidate of every triple: (index of the chosen candidate, its inlier boards,
    its cost).

    Inliers of a candidate: the boards whose error is below ``threshold``, plus the three boards of the triple it
    came from (``union(find(error < threshold), sample)``); cost = sum of the inliers' squared errors +
    ``threshold^2`` x the number of outliers.  The least cost wins; the code's strict ``cost < min_cost`` keeps the
    first of equal costs, in the order of triples (lexicographic, as ``nchoosek``) and of candidates within one
    (``argmin`` keeps the first as well).  A NaN error (a plane through the laser origin) is an outlier; a NaN
    cost never wins.
    """
    E = msac_errors(obs, cands.T_lidar_cam)                                    # (M,N)
    inl = E < threshold
    rows = np.arange(len(E))[:, None]
    inl[rows, cands.triples[cands.triple]] = True
    cost = np.where(inl, E**2, threshold**2).sum(axis=1)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    j = int(np.argmin(cost))
    if not np.isfinite(cost[j]):
        raise SolveFailure("vasconcelos_msac: no candidate has a finite MSAC cost", cands.T_lidar_cam)
    return j, np.flatnonzero(inl[j]), float(cost[j])


MSAC_SOLVER = {"solver": "vasconcelos_dual", "real_parts": True}
"""The authors' P3P keeps the real part of every complex root (``unique(real(roots(...)))``); the candidates such a
root yields depend on the formulation, so they are built in the authors' dual-space one
(``solvers/vasconcelos_dual.py``; its exact solutions are ``solvers/vasconcelos.py``'s)."""


def _msac(obs: Observations, threshold: float, solver_options: dict):
    cands = minimal_candidates(obs, **{**MSAC_SOLVER, **solver_options})
    if len(cands.T_lidar_cam) == 0:
        raise SolveFailure(cands.summary())
    j, inliers, cost = msac_select(obs, cands, threshold)
    info = {"chosen": j, "cost": cost, "scorer": "msac", "msac_threshold_per_mm": threshold,
            "inliers": inliers.tolist(), "sample": cands.triples[cands.triple[j]].tolist(),
            "n_triples": len(cands.triples),
            "n_degenerate_triples": int(sum(r is not None for r in cands.reasons))}
    outliers = sorted(set(range(obs.n_boards)) - set(inliers.tolist()))
    if outliers:
        info["warnings"] = [f"MSAC outlier boards (dual-space error >= {threshold:g} per mm): {outliers}"]
    return cands.T_lidar_cam[j], cands.T_lidar_cam, info


def vasconcelos_msac(obs: Observations, *, threshold: float = MSAC_THRESHOLD_PER_MM, **solver_options):
    """The authors' code's initial solution: MSAC over all triples' minimal solutions (``msac_select``).

    Reproduced from their MATLAB: units (mm) and the z = 10 mm frame of the error (``msac_errors``), the
    threshold 1e-5 per mm, the triple's own boards always inliers, the MSAC cost and its ties
    (``msac_select``), and real parts of complex P3P roots as candidates, built in the authors' dual formulation
    (``MSAC_SOLVER``).  The code's board count (``length(Tp)`` of a 4x4xN array, wrong for N = 3) is taken as N.
    Its answer is expressed in our frame (scan plane z = 0, metres).
    """
    return _msac(obs, threshold, solver_options)


def vasconcelos_msac_refined(obs: Observations, *, threshold: float = MSAC_THRESHOLD_PER_MM,
                             max_nfev: int = MAX_NFEV, **solver_options):
    """The authors' code's default output: the MSAC solution refined on the MSAC inlier boards only.

    Their refinement (``optimizeLaserCamCalib`` with ``Tp(:,:,inl), Pl(inl)``) minimises, by least squares, the
    distance along each beam between the measured point and where the beam meets the board's plane: our range
    residual (``refine(..., residual="range")``); the 10 mm shift of their frame does not change it.  Boards
    outside the inlier set do not enter (``info["boards_used"]``).
    """
    T0, cands, info = _msac(obs, threshold, solver_options)
    used = info["inliers"]
    r = refine(obs.subset(used).scan_data, T0, residual="range", max_nfev=max_nfev)
    info.update(boards_used=used, refine_cost=r.cost, refine_initial_cost=r.initial_cost, refine_nfev=r.nfev)
    return r.T_lidar_cam, np.concatenate([cands, T0[None]]), info


def zhou2014(obs: Observations, **solver_options):
    """Zhou 2014's minimal solver on all board triples, every real solution pooled; the least point-to-plane error
    of all scan points picks the answer.

    The paper itself is not in the material this project could read, so its selection could not be established;
    the point-to-plane choice is ``vasconcelos``'s, which keeps the two minimal solvers comparable (only the
    candidate generator differs).
    """
    cands = minimal_candidates(obs, solver="zhou2014", **solver_options)
    T, info = select_candidate(obs, cands, "point_to_plane")
    return T, cands.T_lidar_cam, info


FRANCISCO_METHODS = (
    Method("vasconcelos_msac", vasconcelos_msac, MIN_BOARDS, VASC_CITE + " (the authors' MATLAB)",
           "the authors' code: minimal solutions of all triples in its dual formulation (real parts of complex roots "
           "kept), MSAC on the dual-space plane-line error (threshold 1e-5 per mm)", cost=EXHAUSTIVE, paper=True,
           options=solver_keywords("vasconcelos_dual") | {"threshold"}),
    Method("vasconcelos_msac_refined", vasconcelos_msac_refined, MIN_BOARDS, VASC_CITE + " (the authors' MATLAB)",
           "the authors' code's default output: vasconcelos_msac refined on range residuals of its inlier boards",
           cost=EXHAUSTIVE, paper=True, options=solver_keywords("vasconcelos_dual") | {"threshold", "max_nfev"}),
    Method("zhou2014", zhou2014, MIN_BOARDS, ZHOU_CITE,
           "Zhou's minimal solver (n_i^T [r1 r2] u_i = 0, orthonormality: up to 8 solutions) on all triples; "
           "least point-to-plane error", cost=EXHAUSTIVE, paper=True, options=solver_keywords("zhou2014")),
)
