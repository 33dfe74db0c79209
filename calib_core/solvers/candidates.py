"""Candidate extrinsics from the minimal solver over all board triples of a problem."""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from ..data.lines import scan_lines, triple_inputs
from ..data.observations import Observations
from ..errors import CalibrationError, SolveFailure
from . import vasconcelos, vasconcelos_dual, zhou2014
from ._common import MIN_BOARDS, board_triples


@dataclass(frozen=True, eq=False)
class CandidateSet:
    """Pooled minimal-solver candidates.

    Attributes:
        T_lidar_cam: (M,4,4) candidates. triple: (M,) index into ``triples`` of the triple each came from.
        triples: (C,3) board indices of every triple solved. reasons: (C,) why a triple gave no solution
        (None where it was solved).
    """

    T_lidar_cam: np.ndarray
    triple: np.ndarray
    triples: np.ndarray
    reasons: np.ndarray

    def summary(self) -> str:
        """Why there are no candidates: counts of the reasons over triples."""
        vals, counts = np.unique([r for r in self.reasons if r is not None], return_counts=True)
        parts = [f"{c}x {v}" for v, c in zip(vals, counts, strict=True)]
        return f"{len(self.triples)} triples, no real solution" + (f" ({'; '.join(parts)})" if parts else "")


MINIMAL_SOLVERS = {"vasconcelos": vasconcelos.solve_triples, "zhou2014": zhou2014.solve_triples,
                   "vasconcelos_dual": vasconcelos_dual.solve_triples}
"""The minimal solvers by name: each ``solve_triples(n, d, p, u, **options) -> MinimalSolutions``."""


def minimal_candidates(obs: Observations, solver: str = "vasconcelos", **solver_options) -> CandidateSet:
    """Run a minimal solver (``MINIMAL_SOLVERS``) on all ``C(N,3)`` board triples and pool the solutions.

    Raises SolveFailure for fewer than 3 boards or a board whose scan line cannot be fitted.
    """
    if obs.n_boards < MIN_BOARDS:
        raise SolveFailure(f"the minimal solver needs at least {MIN_BOARDS} boards, got {obs.n_boards}")
    if solver not in MINIMAL_SOLVERS:
        raise CalibrationError(f"unknown minimal solver {solver!r}; choose from {', '.join(MINIMAL_SOLVERS)}")
    scan_lines(obs).require_line_like()
    tri = board_triples(obs.n_boards)
    sol = MINIMAL_SOLVERS[solver](*triple_inputs(obs, tri), **solver_options)
    return CandidateSet(sol.T_lidar_cam, sol.triple, tri, sol.reasons)


def solver_keywords(solver: str = "vasconcelos") -> frozenset[str]:
    """The keyword options of the minimal solver ``solver`` (``MINIMAL_SOLVERS``): what a method that passes its
    remaining keywords to ``minimal_candidates`` accepts from its caller."""
    sig = inspect.signature(MINIMAL_SOLVERS[solver])
    return frozenset(q.name for q in sig.parameters.values() if q.kind is inspect.Parameter.KEYWORD_ONLY)
