"""Our method, ``lidarcam``, as one forward pipeline over ``LidarcamOptions`` (``methods.options``):

    trim -> hypotheses -> consensus -> choose -> refine -> final tests -> degeneracy -> joint step -> result

Each step is one call into the stage that owns it (``robust.inliers``, ``robust.search``, ``robust.choose``,
``methods.finish``), read top to bottom in ``search_and_refine`` and ``finish``; no stage calls back into the
method.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from ..checks.degeneracy import degeneracy_warnings, explain_failure
from ..data.observations import Observations
from ..errors import SolveFailure
from ..refine.joint import RANGE_ONLY_MODEL
from ..refine.joint_intrinsics import RANGE_ONLY_INTRINSICS
from ..refine.uncertainty import conditioning
from ..registry import Method
from ..robust.choose import Choice, choose_and_refine
from ..robust.inliers import trim
from ..robust.scorers import lidarcam as lidarcam_score
from ..robust.search import FinalTests, Search, consensus_search, final_tests
from .finish import NO_CORNERS, fixed_calibration, range_covariance, refuse_undetermined, try_joint
from .options import FLAT_KEYWORDS, LidarcamOptions


def lidarcam(obs: Observations, *, options: LidarcamOptions | None = None, **keywords):
    """Our method (``LIDARCAM``); ``options`` and/or the flat keywords of ``LidarcamOptions.from_keywords``.

    1. Point-level trimming (``trim``; ``robust.inliers``): scan points off their board's robust line (gross
       outliers, mixed pixels at the ends) are left out.
    2. Consensus over boards (``consensus.reject_boards``; ``robust.search``, ``robust.consensus``): hypotheses from
       the minimal solver on board triples (all while few, sampled adaptively beyond) and Zhang & Pless on sampled
       subsets, scored on every board by a per-board chi-square test of the noise model; local optimisation of the
       best few on their consensus sets. Boards that fail are left out (``info["boards_rejected"]``).
    3. Choose and refine (``robust.choose``) on the consensus boards: every hypothesis computed from them is scored
       with ``scorers.lidarcam`` (range residuals in units of the noise std, estimated from the scan lines unless
       ``range_sigma_m``; endpoint and outline terms; boards behind the camera); the ``refine.n_refine`` best
       distinct ones are refined by maximum likelihood on the range residuals, polished on the whole cost when the
       outlines disagree; the best is kept.
    4. Final tests (``robust.search.final_tests``): a per-board test at the refined pose and a point test (range
       residuals beyond ``inliers.TRIM_SIGMAS`` stds of their board's median one); when they change the boards or
       points, step 3 again from the answer on what is left.
    5. Degeneracy (``methods.finish.refuse_undetermined``): directions the board geometry leaves free (e.g. roll,
       pitch and height z when every board is vertical) are not presented as estimated: ``ok=False``, the reason
       names them and how to calibrate the rest. Directions weak only for lack of data are warned about.
    6. On the boards used: with image corners on every board (``joint.use_corners``), the joint maximum likelihood
       over corners and ranges, covariance with the board poses marginalised (``info["covariance_model"]``
       "joint"); otherwise the range model's covariance (it ignores camera noise).

    ``fixed``: calibrate only the other mounting parameters (``methods.finish.fixed_calibration``), from a
    closed-form start when roll, pitch and z are given (else from the full method's answer).
    """
    opts = LidarcamOptions.from_keywords(options, **keywords)
    if opts.fixed is not None:
        return fixed_calibration(obs, opts.fixed, lambda: search_and_refine(obs, opts).best.T, loss=opts.refine.loss,
                                 f_scale_m=opts.refine.f_scale_m, f_scale_sigmas=opts.refine.f_scale_sigmas,
                                 range_sigma_m=opts.range_sigma_m, max_nfev=opts.refine.max_nfev)
    try:
        found = search_and_refine(obs, opts)                                                     # 1-4
    except SolveFailure as fail:
        raise explain_failure(obs, fail, opts.range_sigma_m) from None
    return finish(found, opts)                                                                   # 5-6


@dataclass(frozen=True, eq=False)
class Found:
    """Steps 1-4 of ``lidarcam``: the search, the chosen and refined answer, its final tests, and the score of
    the start it was refined from."""

    search: Search
    best: Choice
    tests: FinalTests
    score_start: float


def search_and_refine(obs: Observations, opts: LidarcamOptions) -> Found:
    """Trim -> hypotheses -> consensus -> choose -> refine -> final tests (steps 1-4 of ``lidarcam``)."""
    score = opts.score
    obs_t, trim_report = trim(obs, opts.trim)
    search = consensus_search(obs_t, trim_report, range_sigma_m=opts.range_sigma_m,
                              outline_sigma_m=score.outline_sigma_m, options=opts.consensus)
    sigma = search.sigma_m
    best = choose_and_refine(search.obs_used, search.pool, sigma, score, opts.refine, refined=search.refined)
    start = best.cost if np.array_equal(best.start, best.T) else \
        float(lidarcam_score(search.obs_used, best.start[None], range_sigma_m=sigma, **score.kwargs())[0])
    tests = final_tests(search, best.T, reject=opts.consensus.reject_boards)
    if tests.changed:  # boards or points left out (or taken back) at the refined pose: refine on what is left
        best = choose_and_refine(tests.obs_used, best.T, sigma, score, opts.refine, n_refine=1)
    return Found(search, best, tests, start)


def finish(found: Found, opts: LidarcamOptions):
    """Degeneracy -> joint step or the range covariance -> result (steps 5-6 of ``lidarcam``): (T_lidar_cam,
    candidates, info)."""
    best, tests, C, sigma_given = found.best, found.tests, found.search.all_candidates, opts.range_sigma_m
    obs_u = tests.obs_used
    deg = refuse_undetermined(obs_u, best.T, np.concatenate([best.T[None], C]), "lidarcam", sigma_given,
                              opts.degeneracy)
    joint, why = try_joint(obs_u, best.T, range_sigma_m=sigma_given, loss=opts.refine.loss, options=opts.joint)
    if joint is not None:
        T, cov, jinfo = joint
    else:
        T, cov = best.T, range_covariance(obs_u, best.T, C, "lidarcam", range_sigma_m=sigma_given)
        jinfo = {"covariance_model": RANGE_ONLY_MODEL, "intrinsics": RANGE_ONLY_INTRINSICS}
        if why is not None and why != NO_CORNERS:
            jinfo["warnings"] = [f"{why}; covariance of the range model only"]
    warnings = tests.warnings + jinfo.pop("warnings", []) + degeneracy_warnings(obs_u, T) + \
        ([deg.message()] if len(deg.directions) else [])
    return T, C, {"cost": best.cost, "polished": best.polished, "score_start": found.score_start,
                  "n_refined": opts.refine.n_refine, "sigma_m_selection": found.search.sigma_m,
                  "refine_cost": best.refined.cost, "refine_nfev": best.refined.nfev, **tests.info, "covariance": cov,
                  "conditioning": conditioning(obs_u, T), "warnings": warnings, **jinfo}


def _signature() -> inspect.Signature:
    """``lidarcam``'s signature as callers see it: the observations, ``options`` and every flat keyword by name
    (``**solver`` for the minimal solver's), so that ``inspect.signature`` lists the options it takes."""
    P = inspect.Parameter
    return inspect.Signature([P("obs", P.POSITIONAL_OR_KEYWORD), P("options", P.KEYWORD_ONLY, default=None),
                              *(P(k, P.KEYWORD_ONLY, default=None) for k in FLAT_KEYWORDS),
                              P("solver_options", P.VAR_KEYWORD)])


lidarcam.__signature__ = _signature()

LIDARCAM = Method("lidarcam", lidarcam, 3, "this project (lidarcam)",
                  "point trimming; consensus over boards (minimal-solver triples + Zhang & Pless subsets, "
                  "per-board chi-square tests; inconsistent boards rejected and named); all-evidence likelihood "
                  "selection; ML refinement of the best few; covariance and degeneracy warnings",
                  cost="about linear in N: all C(N,3) triples up to 12 boards, then an "
                  "adaptively sampled, bounded set; per-board tests O(hypotheses x N)")

