"""``LidarcamOptions``: every option of the default method in one frozen value, in parts owned by the stages that
read them (trim, consensus, score, choose, degeneracy, joint), passed whole through the pipeline.

``calibrate(obs, "lidarcam", **kw)`` takes the flat keywords of ``FLAT_KEYWORDS`` (and the minimal solver's
options), mapped here onto the parts; ``options=LidarcamOptions(...)`` gives the whole value. ``f_scale`` (the
name of the option before the scales carried their unit) is ``choose.f_scale_m``, in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..checks.degeneracy import DegeneracyOptions
from ..errors import CalibrationError
from ..model.score import ScoreOptions
from ..refine.joint import JointOptions
from ..registry import RENAMED_OPTIONS as RENAMED
from ..robust.choose import ChooseOptions
from ..robust.inliers import TrimOptions
from ..robust.search import ConsensusOptions
from ..solvers.candidates import solver_keywords


@dataclass(frozen=True)
class LidarcamOptions:
    """The options of ``lidarcam``.

    Attributes:
        range_sigma_m: the range-noise std (metres); None: estimated from the scan lines (``data.lines``).
        fixed: mounting parameters held at given values (``geometry.mounting`` names, e.g. ``{"z_m": 0.12}``):
            calibrate only the others.
        trim, consensus, score, choose, degeneracy, joint: the stages' options.
    """

    range_sigma_m: float | None = None
    fixed: dict | None = None
    trim: TrimOptions = field(default_factory=TrimOptions)
    consensus: ConsensusOptions = field(default_factory=ConsensusOptions)
    score: ScoreOptions = field(default_factory=ScoreOptions)
    choose: ChooseOptions = field(default_factory=ChooseOptions)
    degeneracy: DegeneracyOptions = field(default_factory=DegeneracyOptions)
    joint: JointOptions = field(default_factory=JointOptions)

    @classmethod
    def from_keywords(cls, options: LidarcamOptions | None = None, **kw) -> LidarcamOptions:
        """``options`` (default: the defaults) with the flat keywords ``kw`` applied; CalibrationError naming an
        unknown one."""
        base = options if options is not None else cls()
        if not isinstance(base, LidarcamOptions):
            raise CalibrationError(f"lidarcam: options must be a LidarcamOptions, got {type(base).__name__}")
        top, parts, solver = {}, {}, dict(base.consensus.solver)
        for key, value in kw.items():
            if key in SOLVER_KEYWORDS:
                solver[key] = value
                continue
            if key in RENAMED:
                raise CalibrationError(f"lidarcam: option {key!r} is now {RENAMED[key]}")
            if key not in FLAT_KEYWORDS:
                raise CalibrationError(f"lidarcam: unknown option {key!r}; known: "
                                       f"{', '.join(sorted({*FLAT_KEYWORDS, *SOLVER_KEYWORDS}))}")
            part, name = FLAT_KEYWORDS[key]
            if part is None:
                top[name] = value
            else:
                parts.setdefault(part, {})[name] = value
        parts.setdefault("consensus", {})["solver"] = tuple(sorted(solver.items()))
        return replace(base, **top, **{p: replace(getattr(base, p), **v) for p, v in parts.items()})


FLAT_KEYWORDS: dict[str, tuple[str | None, str]] = {
    "range_sigma_m": (None, "range_sigma_m"), "fixed": (None, "fixed"),
    "trim_points": ("trim", "enabled"), "trim_sigmas": ("trim", "n_sigmas"), "max_trim_share": ("trim", "max_share"),
    "reject_boards": ("consensus", "reject_boards"), "use_zhang_pless": ("consensus", "use_zhang_pless"),
    "edge_sigma_m": ("score", "edge_sigma_m"), "outline_sigma_m": ("score", "outline_sigma_m"),
    "behind_penalty": ("score", "behind_penalty"), "prior": ("score", "prior"),
    "chord_sigma_m": ("score", "chord_sigma_m"), "chord_cap": ("score", "chord_cap"),
    "margin_sigma_m": ("score", "margin_sigma_m"), "tie_log_likelihood": ("choose", "tie_log_likelihood"),
    "n_refine": ("choose", "n_refine"), "loss": ("choose", "loss"), "f_scale_m": ("choose", "f_scale_m"),
    "f_scale_sigmas": ("choose", "f_scale_sigmas"),
    "max_nfev": ("choose", "max_nfev"), "polish": ("choose", "polish"),
    "polish_threshold": ("choose", "polish_threshold"),
    "distinct_rot_deg": ("choose", "distinct_rot_deg"), "distinct_trans_m": ("choose", "distinct_trans_m"),
    "null_conditioning": ("degeneracy", "null_conditioning"), "max_scaled_sigma": ("degeneracy", "max_scaled_sigma"),
    "use_corners": ("joint", "use_corners"), "corner_sigma_px": ("joint", "corner_sigma_px"),
    "joint_f_scale_sigmas": ("joint", "f_scale_sigmas"), "joint_max_iter": ("joint", "max_iter"),
    "widen": ("joint", "widen"), "joint_outline": ("joint", "outline"), "bend": ("joint", "bend"),
    "board_error": ("joint", "board_error"),
}
"""Flat keywords of ``calibrate(obs, "lidarcam", ...)`` and the (part, field) each sets (part None: the top)."""
SOLVER_KEYWORDS = solver_keywords("vasconcelos")
"""Keywords that go to the minimal solver (``ConsensusOptions.solver``)."""
