"""Our method, ``lidarcam``, as one forward pipeline over ``LidarcamOptions`` (``methods.options``):

    1. trim -> 2. consensus -> 3. choose and refine -> 4. final tests -> 5. degeneracy -> 6. joint step -> result

(the same six steps as ``lidarcam``'s docstring and docs/lidarcam.md). Each step is one call into the stage that
owns it (``robust.inliers``, ``robust.search``, ``robust.choose``, ``robust.final``, ``methods.last_steps``), read top
to bottom in ``search_and_refine`` (steps 1-4) and ``finish`` (steps 5-6); the terms every step scores with live in
``model/``; no stage calls back into the method.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..checks.degeneracy import Degeneracy, degeneracy_warnings, explain_failure
from ..data.lines import range_sigma, residual_sigma
from ..data.observations import Observations
from ..data.outcome import BoardErrorPart, ChoicePart, CovariancePart, InfoParts, JointFitPart, NoiseModel
from ..errors import CalibrationError, SolveFailure
from ..geometry.mounting import params_from_T, with_units
from ..model.intrinsics import ESTIMATED_INTRINSICS, RANGE_ONLY_INTRINSICS
from ..model.residuals import range_linearised
from ..model.score import evidence_cost
from ..refine.joint import RANGE_ONLY_MODEL
from ..refine.modes import mixture_covariance
from ..refine.systematic import ESTIMATED, BoardErrorEstimate, board_error_estimate
from ..refine.uncertainty import conditioning
from ..registry import Method
from ..robust.choose import (
    TIE_LOG_LIKELIHOOD,
    WEAK_LOG_LIKELIHOOD,
    Choice,
    carried_runners_up,
    choose_and_refine,
)
from ..robust.final import FinalTests, final_tests
from ..robust.inliers import trim
from ..robust.search import Search, consensus_search
from ..solvers._common import MIN_BOARDS
from .last_steps import (
    NO_CORNERS,
    fixed_calibration,
    fold_covariance,
    prior_contradiction,
    prior_fixed,
    prior_info,
    profile_floor,
    range_covariance,
    refuse_undetermined,
    try_joint,
    undetermined_failure,
    widened_range_covariance,
    with_prior,
)
from .options import FLAT_KEYWORDS, SOLVER_KEYWORDS, LidarcamOptions


def lidarcam(obs: Observations, *, options: LidarcamOptions | None = None, **keywords):
    """Our method (``LIDARCAM``); ``options`` and/or the flat keywords of ``LidarcamOptions.from_keywords``.

    1. Point-level trimming (``trim``; ``robust.inliers``): scan points off their board's robust line (gross
       outliers, mixed pixels at the ends) are left out.
    2. Consensus over boards (``consensus.reject_boards``; ``robust.search``, ``robust.consensus``): hypotheses from
       the minimal solver on board triples (all while few, sampled adaptively beyond) and Zhang & Pless on sampled
       subsets, scored on every board by a per-board chi-square test of the noise model; local optimisation of the
       best few on their consensus sets. Boards that fail are left out (``info["boards_rejected"]``).
    3. Choose and refine (``robust.choose``) on the consensus boards: every hypothesis computed from them is scored
       with ``score.evidence_cost`` (range residuals in units of the noise std, estimated from the scan lines unless
       ``range_sigma_m``; endpoint and outline terms; boards behind the camera); the ``choose.n_refine`` best
       distinct ones are refined by maximum likelihood on the range residuals, polished on the whole cost when the
       outlines disagree; the best is kept.
    4. Final tests (``robust.final.final_tests``): a per-board test at the refined pose and a point test (range
       residuals beyond ``inliers.TRIM_SIGMAS`` stds of their board's median one); when they change the boards or
       points, step 3 again from the answer on what is left.
    5. Degeneracy (``methods.last_steps.refuse_undetermined``): directions the data leave free (their profile
       likelihood flat across the physically possible range, ``checks.profile.FREE_SPAN``: e.g. height z when
       every board stands exactly vertical) are not presented as estimated: ``ok=False``, the reason names them and
       how to calibrate the rest. Weak directions are answered with their large 1-sigma and warned about: boards
       that lean a little fix roll, pitch and z with the larger of the linear and the profile 1-sigma, to which the
       covariance is widened (``last_steps.profile_floor``); so is a fold (three boards' solutions meeting at the
       answer: no first-order information along one direction, its sigma from the profile likelihood,
       ``checks.profile``); where the joint step fails there (its linearisation
       is singular too), the covariance is ``last_steps.fold_covariance``.
    6. On the boards used: with image corners on every board (``joint.use_corners``), the joint maximum likelihood
       over corners and ranges, covariance with the board poses marginalised (``info["covariance_model"]``
       "joint"); otherwise the range model's covariance (it ignores camera noise).

    ``fixed``: calibrate only the other mounting parameters (``methods.last_steps.fixed_calibration``), from a
    closed-form start when roll, pitch and z are given (else from the full method's answer).
    """
    opts = LidarcamOptions.from_keywords(options, **keywords)
    if opts.fixed is not None and opts.score.prior is not None:
        raise CalibrationError("lidarcam: a mounting prior and fixed parameters do not go together (fix what "
                               "is known, or give it as the prior)")
    if opts.fixed is not None:
        T, starts, parts = fixed_calibration(obs, opts.fixed, lambda: search_and_refine(obs, opts).best.T,
                                             opts.choose, range_sigma_m=opts.range_sigma_m)
        return T, starts, parts.to_info()
    try:
        found = search_and_refine(obs, opts)                                                     # 1-4
    except SolveFailure as fail:
        raise explain_failure(obs, fail, opts.range_sigma_m) from None
    return finish(found, opts)                                                                   # 5-6


@dataclass(frozen=True, eq=False)
class Found:
    """Steps 1-4 of ``lidarcam``: the search, the chosen and refined answer (its ``runners_up`` scored on the
    boards and points it was chosen on: those of the choice before the final tests, refined again after them where
    the tests changed the boards or points), its final tests, the score of the start it was refined from, and
    ``first``: the choice before the final tests."""

    search: Search
    best: Choice
    tests: FinalTests
    score_start: float
    first: Choice


def search_and_refine(obs: Observations, opts: LidarcamOptions) -> Found:
    """Steps 1-4 of ``lidarcam``: trim -> consensus -> choose and refine -> final tests."""
    score = opts.score
    obs_t, trim_report = trim(obs, opts.trim)
    search = consensus_search(obs_t, trim_report, range_sigma_m=opts.range_sigma_m,
                              outline_sigma_m=score.outline_sigma_m, options=opts.consensus,
                              prior=score.prior)
    sigma = search.sigma_m
    best = choose_and_refine(search.obs_used, search.pool, sigma, score, opts.choose, refined=search.refined)
    if best.ties:
        raise tie_failure(best, search.hypotheses_T, score.prior is not None, opts.choose.tie_log_likelihood)
    if not np.isfinite(best.cost):
        raise SolveFailure("lidarcam: every refined answer puts some board in an implausible place (behind a sensor, "
                           "or the sensors on opposite sides of its plane)", search.hypotheses_T)
    start = best.cost if np.array_equal(best.start, best.T) else \
        float(evidence_cost(search.obs_used, best.start[None], range_sigma_m=sigma, **score.kwargs())[0])
    tests = final_tests(search, best.T, reject=opts.consensus.reject_boards)
    first = best
    if tests.changed:  # boards or points left out (or taken back) at the refined pose: refine on what is left
        best = choose_and_refine(tests.obs_used, best.T, sigma, score, opts.choose, n_refine=1)
        best = carried_runners_up(tests.obs_used, best, first.runners_up, sigma, score, opts.choose)
    return Found(search, best, tests, start, first)


def alternatives(answers) -> list[dict]:
    """``info["alternatives"]``: each (T, cost) as ``{"T_lidar_cam": 4x4 list, "cost", "mounting"}``."""
    return [{"T_lidar_cam": np.asarray(T).tolist(), "cost": float(c), "mounting": with_units(params_from_T(T))}
            for T, c in answers]


def named(alts: list[dict]) -> str:
    """The answers of ``alternatives`` for a reason or a warning: each cost and its mounting parameters."""
    return "; ".join(f"cost {a['cost']:.6g}: " + ", ".join(f"{k} {v:.3g}" for k, v in a["mounting"].items())
                     for a in alts)


def runner_up_warning(best: Choice, modes: dict | None = None) -> tuple[list[str], dict]:
    """A warning naming the distinct answers nearly as likely as ``best`` (``choose.WEAK_LOG_LIKELIHOOD``) and
    the ``alternatives`` entry (the answer first), or nothing when the data prefer it clearly; ``modes``: the
    covariance that holds them (``refine.modes.mixture_covariance``'s report), named in the warning."""
    if not best.runners_up:
        return [], {}
    alts = alternatives([(best.T, best.cost), *best.runners_up])
    held = "" if not modes else \
        (f"; the 1-sigma holds them (likelihood-weighted mixture of the {modes['n_modes']} answers: "
         f"{modes['sigma_rot_deg']:.3g} deg, {modes['sigma_trans_mm']:.3g} mm; the answer's own mode: "
         f"{modes['sigma_rot_deg_mode']:.3g} deg, {modes['sigma_trans_mm_mode']:.3g} mm)")
    better = "" if min(c for _, c in best.runners_up) >= best.cost else \
        " (refined again after the final tests, one fits these boards better than the answer chosen before them)"
    return [f"weakly decided: distinct answers nearly as likely (within {WEAK_LOG_LIKELIHOOD:g} in log-likelihood; "
            f"the answer first): {named(alts)}{better}; a mounting prior or more boards would decide{held}"], \
        {"alternatives": alts, **({"covariance_modes": modes} if modes else {})}


def tie_failure(best: Choice, candidates: np.ndarray, with_prior: bool,
                tie: float = TIE_LOG_LIKELIHOOD) -> SolveFailure:
    """The refusal of a tie (``choose.TIE_LOG_LIKELIHOOD``): the reason names every tied answer (as mounting
    parameters) and its cost; ``info["alternatives"]`` holds each as ``{"T_lidar_cam", "cost", "mounting"}``, best
    first."""
    alts = alternatives([(best.T, best.cost), *best.ties])
    hint = "the mounting prior given does not separate them" if with_prior else \
        "a mounting prior (calibrate(obs, prior=MountingPrior...), CLI --prior/--prior-sigma) or more boards decide"
    return SolveFailure(f"lidarcam: the data do not decide between {len(alts)} distinct answers (costs within "
                        f"{tie:g} of each other in log-likelihood): {named(alts)}; {hint}", candidates,
                        {"alternatives": alts})


def finish(found: Found, opts: LidarcamOptions):
    """Degeneracy -> joint step or the range covariance -> result (steps 5-6 of ``lidarcam``): (T_lidar_cam,
    candidates, info)."""
    best, tests, C, sigma_given = found.best, found.tests, found.search.hypotheses_T, opts.range_sigma_m
    obs_u = tests.obs_used
    prior = opts.score.prior
    deg = refuse_undetermined(obs_u, best.T, np.concatenate([best.T[None], C]), "lidarcam", sigma_given,
                              opts.degeneracy, refuse=prior is None)
    est = board_error_estimate(obs_u, best.T, sigma_given) if opts.joint.board_error else None
    if not deg.determined:              # a mounting prior given: it decides the axes the boards leave free
        return prior_decides(found, opts, deg, est)
    term = None if est is None else est.scale
    held = est is not None and est.source == ESTIMATED  # the boards' spread is in the term: no widening on top
    joint, why = try_joint(obs_u, best.T, range_sigma_m=sigma_given, loss=opts.choose.loss, options=opts.joint,
                           names=tests.info.get("boards_used"), mounting=prior, board_error=term, spread_held=held)
    if joint is not None:
        T, part, fit, warned = joint.T_lidar_cam, joint.covariance, joint.fit, joint.warnings
        cov = profile_floor(T, part.matrix, deg)
        if prior is not None:  # the joint model's answer is the posterior's mode; its covariance the data's
            warned.extend(filter(None, [prior_contradiction(T, cov, prior)]))
            cov = with_prior(T, cov, prior)
    else:
        T, fit, cov = best.T, None, fold_covariance(obs_u, best.T, deg, term) if deg.profile.any() else \
            range_covariance(obs_u, best.T, C, "lidarcam", range_sigma_m=sigma_given, board_error=term)
        disp, warned = None, []
        if opts.joint.widen:
            cov, disp, warned = widened_range_covariance(obs_u, T, cov, sigma_given, tests.info.get("boards_used"),
                                                         term, held)
        cov = profile_floor(T, cov, deg)
        if prior is not None:  # the refinement held the prior already: its information only
            warned.extend(filter(None, [prior_contradiction(T, cov, prior)]))
            cov = with_prior(T, cov, prior)
        if why is not None and why != NO_CORNERS:
            warned.append(f"{why}; covariance of the range model only")
        part = CovariancePart(cov, RANGE_ONLY_MODEL, RANGE_ONLY_INTRINSICS, dispersion=disp)
    cov, modes = mixture_covariance(T, cov, best.cost, best.runners_up)  # last: it composes the modes
    weak, alts = runner_up_warning(best, modes)
    warnings = tests.warnings + warned + degeneracy_warnings(obs_u, T) + \
        ([deg.message()] if len(deg.directions) else []) + weak
    choice = ChoicePart(best.cost, best.polished, found.score_start, opts.choose.n_refine, best.start,
                        found.search.sigma_m, best.refined.cost, best.refined.nfev)
    nm = noise_model(obs_u, T, fit, part.intrinsics, sigma_given, opts.joint.corner_sigma_px, est,
                     fold=joint is None and bool(deg.profile.any()))
    return T, C, InfoParts(choice=choice, consensus=tests.info, prior=None if prior is None else prior_info(prior),
                           covariance=replace(part, matrix=cov, conditioning=conditioning(obs_u, T),
                                              modes=alts.get("covariance_modes")), joint=fit,
                           alternatives=alts.get("alternatives"), board_error=None if est is None else est.to_dict(),
                           noise_model=nm, warnings=warnings).to_info()


def noise_model(obs: Observations, T: np.ndarray, fit: JointFitPart | None, intrinsics: str,
                sigma_given: float | None, corner_given: float | None, est: BoardErrorEstimate | None,
                fold: bool = False) -> NoiseModel:
    """``info["noise_model"]`` of ``finish`` and ``prior_decides``: the covariance's noise model, each scale with
    its value and source (``fit``: the joint model's, None for the range model; ``intrinsics``: how the camera's
    intrinsics entered the covariance, ``model.intrinsics``' wording)."""
    term = est is not None and est.scale.active
    joint = fit is not None
    if sigma_given is not None:
        r, r_src = float(sigma_given), "stated"
    elif term or fold:
        r, r_src = range_sigma(obs), "scan lines"
    elif joint:
        r, r_src = float(fit.range_sigma_m), "range residuals"
    else:
        r, r_src = residual_sigma(range_linearised(T, obs.scan_data)[0], 6), "range residuals"
    parts = ["per-beam range noise"] + (["a per-board offset and tilt of the lidar's plane"] if term else []) + \
        (["image-corner noise (board poses estimated)"] if joint else ["board poses taken as exact"])
    if joint and intrinsics == ESTIMATED_INTRINSICS:
        parts.append("the intrinsics' stated 1-sigma")
    return NoiseModel(", ".join(parts), r, r_src, None if fit is None else fit.corner_sigma_px,
                      None if not joint else "stated" if corner_given is not None else "estimated", intrinsics,
                      BoardErrorPart.from_info({"board_error": est.to_dict()}) if term else None)


def prior_decides(found: Found, opts: LidarcamOptions, deg: Degeneracy, est: BoardErrorEstimate | None = None):
    """Where the boards leave axes free (``deg``) and a mounting prior is given: those axes held at the prior's
    values with its 1-sigma, the others calibrated on the scans (``methods.finish.fixed_calibration``, the range
    model, holding the per-board systematic error ``est`` where given), the prior's uncertainty carried into the
    covariance. Axes free only in combination (``deg.aligned`` false) cannot be held one by one: refused as
    without a prior. (T_lidar_cam, candidates, info)."""
    best, tests, C, prior = found.best, found.tests, found.search.hypotheses_T, opts.score.prior
    if not deg.aligned:
        raise undetermined_failure(tests.obs_used, deg, np.concatenate([best.T[None], C]), "lidarcam")
    fixed, sigma = prior_fixed(prior, deg)
    T, _, parts = fixed_calibration(tests.obs_used, fixed, lambda: best.T, opts.choose,
                                    range_sigma_m=opts.range_sigma_m, fixed_sigma=sigma,
                                    board_error=None if est is None else est.scale)
    warnings = tests.warnings + parts.warnings + [deg.message(from_prior=True)]
    cov = CovariancePart(parts.refinement["covariance"], RANGE_ONLY_MODEL, RANGE_ONLY_INTRINSICS)
    nm = noise_model(tests.obs_used, T, None, RANGE_ONLY_INTRINSICS, opts.range_sigma_m, None, est)
    return T, C, replace(parts, consensus=tests.info, prior=prior_info(prior), covariance=cov,
                         degeneracy=deg.to_dict(), board_error=None if est is None else est.to_dict(),
                         noise_model=nm, warnings=warnings).to_info()


LIDARCAM = Method("lidarcam", lidarcam, MIN_BOARDS, "this project (lidarcam)",
                  "point trimming; consensus over boards (minimal-solver triples + Zhang & Pless subsets, "
                  "per-board chi-square tests; inconsistent boards rejected and named); all-evidence likelihood "
                  "selection; ML refinement of the best few; covariance and degeneracy warnings",
                  cost="about linear in N: all C(N,3) triples up to 12 boards, then an "
                  "adaptively sampled, bounded set; per-board tests O(hypotheses x N)",
                  options=frozenset({"options", *FLAT_KEYWORDS, *SOLVER_KEYWORDS}) - {"prior"}, takes_prior=True)

