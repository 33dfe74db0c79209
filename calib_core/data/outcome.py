"""The result's parts as types (``CalibrationResult.outcome``): the noise estimates named by their source, the
consensus over boards, the selection, the covariance with its model as an enum, the verdict and the warnings; read
from the same ``info`` that the ``lidarcam.result/1`` file holds, so a loaded file gives the same parts. Metres and
radians, except where a name says otherwise.

The other way, the parts a method hands over (``InfoParts``: its choice, the covariance with its model, the joint
fit, the noise model, ...) become the ``info`` dict in one place, ``InfoParts.to_info``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np


class CovarianceModel(StrEnum):
    """What a result's covariance models (its value is the file's ``covariance_model`` text)."""

    JOINT = "joint"
    """Image corners and ranges, board poses estimated, intrinsics taken as exact."""
    JOINT_INTRINSICS = "joint, intrinsics uncertain"
    """As ``JOINT``, with the stated 1-sigma of the intrinsics carried as a prior."""
    RANGE_ONLY = "range-only, ignores camera noise"
    """The ranges alone, the board poses taken as exact."""
    OTHER = "other"
    """A plugin's own wording (kept as ``Covariance.model_text``)."""


def _float(value) -> float | None:
    return None if value is None else float(value)


@dataclass(frozen=True)
class Noise:
    """The range-noise figures of one result, each named by what it is (metres; None where not computed):
    ``scan_lines_m`` the scan lines' residual std the search scored with, ``trimmed_m`` the pooled std of the
    points kept after trimming, ``joint_m`` the joint model's estimate at the answer, ``verdict_spread_m`` the
    robust spread the consistency verdict tested against (with its pose floor)."""

    scan_lines_m: float | None = None
    trimmed_m: float | None = None
    joint_m: float | None = None
    verdict_spread_m: float | None = None

    @classmethod
    def from_info(cls, info: dict) -> Noise:
        if info.get("noise") is not None:  # a loaded file: the figures by name
            return cls(**{k: _float(v) for k, v in info["noise"].items() if k in cls.__dataclass_fields__})
        return cls(_float(info.get("sigma_m_selection")), _float((info.get("points_trimmed") or {}).get("sigma_m")),
                   _float(info.get("range_sigma_m")), _float((info.get("verdict") or {}).get("sigma_m")))

    def to_dict(self) -> dict | None:
        """The file's optional ``noise`` field (metres by name), or None when no figure was computed."""
        d = asdict(self)
        return d if any(v is not None for v in d.values()) else None


@dataclass(frozen=True)
class BoardErrorPart:
    """The per-board systematic error the model held (``calib_core.model.board_error``; metres): ``offset_m`` along
    the board normal, ``tilt_m`` as the RMS displacement of a board's scan points, where they came from
    (``source``: ``"stated"`` by the observation file, ``"estimated"`` from the boards by restricted maximum
    likelihood, or ``"prior"``), the boards' degrees of freedom for them, the estimate's 1-sigma (None unless
    estimated) and the prior's values."""

    offset_m: float
    tilt_m: float
    source: str
    dof: int | None = None
    se_offset_m: float | None = None
    se_tilt_m: float | None = None
    prior_offset_m: float | None = None
    prior_tilt_m: float | None = None

    @classmethod
    def from_info(cls, info: dict) -> BoardErrorPart | None:
        d = info.get("board_error")
        if d is None:
            return None
        return cls(float(d["offset_m"]), float(d["tilt_m"]), str(d["source"]), d.get("dof"),
                   _float(d.get("se_offset_m")), _float(d.get("se_tilt_m")), _float(d.get("prior_offset_m")),
                   _float(d.get("prior_tilt_m")))


@dataclass(frozen=True)
class NoiseModel:
    """The noise model a result's covariance holds, each scale with its value and where it came from:
    ``range_sigma_m`` the per-beam range noise (``range_source``: ``"stated"``, ``"scan lines"`` (the scatter
    about each board's own line) or ``"range residuals"`` (about the answer's planes, boards' own errors
    included)), ``corner_sigma_px`` the corner noise (``corner_source``: ``"stated"`` or ``"estimated"``; None
    without corners), ``intrinsics`` how the camera's intrinsics entered, and ``board_error`` the per-board
    systematic error (None where the model holds none). ``name`` says it in words."""

    name: str
    range_sigma_m: float | None = None
    range_source: str | None = None
    corner_sigma_px: float | None = None
    corner_source: str | None = None
    intrinsics: str | None = None
    board_error: BoardErrorPart | None = None

    @classmethod
    def from_info(cls, info: dict) -> NoiseModel | None:
        d = info.get("noise_model")
        if d is None:
            return None
        return cls(str(d.get("name")), _float(d.get("range_sigma_m")), d.get("range_source"),
                   _float(d.get("corner_sigma_px")), d.get("corner_source"), d.get("intrinsics"),
                   BoardErrorPart.from_info(info))

    def to_dict(self) -> dict:
        """The file's optional ``noise_model`` field (the board error is its own field, ``board_error``)."""
        d = asdict(self)
        d.pop("board_error")
        return d


@dataclass(frozen=True)
class Consensus:
    """The boards the answer rests on and those left out (``{"index", "reason", "statistic"}``), the points
    trimmed, and how many hypotheses the search drew (None where the method has no search)."""

    boards_used: tuple[int, ...] | None = None
    boards_rejected: tuple[dict, ...] = ()
    points_trimmed: int = 0
    hypotheses: int | None = None

    @classmethod
    def from_info(cls, info: dict) -> Consensus:
        used = info.get("boards_used")
        return cls(None if used is None else tuple(int(i) for i in used),
                   tuple(dict(r) for r in info.get("boards_rejected", [])),
                   int((info.get("points_trimmed") or {}).get("total", 0)),
                   (info.get("consensus") or {}).get("n_hypotheses"))


@dataclass(frozen=True)
class Selection:
    """The chosen answer's cost (its negative log-likelihood, or the method's own cost), the cost of the candidate
    it was refined from, whether the polish moved it, and the answers a refused tie could not decide between."""

    cost: float | None = None
    start_cost: float | None = None
    polished: bool | None = None
    alternatives: tuple[dict, ...] = ()

    @classmethod
    def from_info(cls, info: dict) -> Selection:
        return cls(_float(info.get("cost")), _float(info.get("score_start")), info.get("polished"),
                   tuple(info.get("alternatives") or ()))


@dataclass(frozen=True)
class Covariance:
    """The covariance's model, its text as written, how the intrinsics entered, the boards' dispersion test and the
    likelihood's bend it holds (each a dict as in the file, or None)."""

    model: CovarianceModel | None = None
    model_text: str | None = None
    intrinsics: str | None = None
    dispersion: dict | None = None
    bend: dict | None = None

    @classmethod
    def from_info(cls, info: dict) -> Covariance:
        text = info.get("covariance_model")
        model = None if text is None else CovarianceModel(text) if text in CovarianceModel._value2member_map_ \
            else CovarianceModel.OTHER
        return cls(model, None if text is None else str(text), info.get("intrinsics"), info.get("board_dispersion"),
                   info.get("covariance_bend"))


@dataclass(frozen=True)
class VerdictPart:
    """The consistency verdict of the answer: consistent (None where the method failed first), the reason, its
    warnings and the likely causes it names."""

    consistent: bool | None = None
    reason: str | None = None
    warnings: tuple[str, ...] = ()
    causes: tuple[str, ...] = ()
    sigma_m: float | None = field(default=None, compare=False)
    """The noise std the tests used (metres; None where the method failed before the tests)."""
    boards: tuple[dict, ...] | None = field(default=None, compare=False)
    """Per board, the test statistics (dicts of plain numbers; None where the method failed first)."""

    @classmethod
    def from_info(cls, info: dict) -> VerdictPart | None:
        v = info.get("verdict")
        if v is None:
            return None
        boards = v.get("boards")
        return cls(v.get("consistent"), v.get("reason"), tuple(v.get("warnings", ())), tuple(v.get("causes", ())),
                   _float(v.get("sigma_m")), None if boards is None else tuple(boards))

    def to_dict(self) -> dict:
        """The ``info["verdict"]`` entry (the file's ``verdict`` field); ``sigma_m`` and ``boards`` only where the
        tests ran."""
        d = {"consistent": None if self.consistent is None else bool(self.consistent), "reason": self.reason,
             "warnings": list(self.warnings), "causes": list(self.causes)}
        if self.sigma_m is not None:
            d["sigma_m"] = float(self.sigma_m)
        if self.boards is not None:
            d["boards"] = list(self.boards)
        return d


@dataclass(frozen=True)
class ResidualRmsPart:
    """The range residuals' RMS (metres) over the boards the answer rests on, at the method's start
    (``start_m``; None where the method has no start) and at its answer (``answer_m``; None where not finite)."""

    start_m: float | None
    answer_m: float | None

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class ObservationsPart:
    """Which observations a result was computed from (``data.result.observations_fingerprint``): the number of
    boards and the SHA-256 (hex) over their data."""

    boards: int
    sha256: str

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Outcome:
    """Every part of a result beside the extrinsic and its covariance matrix."""

    noise: Noise
    consensus: Consensus
    selection: Selection
    covariance: Covariance
    verdict: VerdictPart | None
    warnings: tuple[str, ...]
    residual_rms: dict[str, Any] | None = None
    noise_model: NoiseModel | None = None

    @classmethod
    def from_info(cls, info: dict) -> Outcome:
        return cls(Noise.from_info(info), Consensus.from_info(info), Selection.from_info(info),
                   Covariance.from_info(info), VerdictPart.from_info(info),
                   tuple(str(w) for w in info.get("warnings", [])), info.get("residual_rms"),
                   NoiseModel.from_info(info))


@dataclass(frozen=True, eq=False)
class CovariancePart:
    """A method's covariance as it hands it over: the 6x6 ``matrix`` (rotation rad then translation m, the left
    perturbation of ``model.residuals``), the ``model`` it comes from, how the camera's ``intrinsics`` entered
    (``model.intrinsics``' wording), the answer's ``conditioning`` (``refine.uncertainty.conditioning``), the
    boards' dispersion test (``refine.dispersion``), the likelihood's bend (``refine.bend``) and the nearly tied
    answers it holds (``refine.modes``), each as the file writes it; None: no entry."""

    matrix: np.ndarray
    model: CovarianceModel
    intrinsics: str
    conditioning: float | None = None
    dispersion: dict | None = None
    bend: dict | None = None
    modes: dict | None = None

    def entries(self) -> dict:
        d = {"covariance": self.matrix, "covariance_model": self.model, "intrinsics": self.intrinsics}
        d.update({k: v for k, v in (("conditioning", self.conditioning), ("board_dispersion", self.dispersion),
                                     ("covariance_bend", self.bend), ("covariance_modes", self.modes))
                       if v is not None})
        return d


@dataclass(frozen=True)
class JointFitPart:
    """The joint model's fit at the answer (``refine.joint.JointResult``): the noise stds it used (given or
    estimated; pixels, metres), its residuals' RMS, its cost, iterations and whether it converged."""

    corner_sigma_px: float
    range_sigma_m: float
    corner_rms_px: float
    range_rms_m: float
    cost: float
    iterations: int
    converged: bool

    def entries(self) -> dict:
        return {"corner_sigma_px": self.corner_sigma_px, "range_sigma_m": self.range_sigma_m,
                "corner_rms_px": self.corner_rms_px, "range_rms_m": self.range_rms_m, "joint_cost": self.cost,
                "joint_iterations": self.iterations, "joint_converged": self.converged}


@dataclass(frozen=True, eq=False)
class ChoicePart:
    """``lidarcam``'s choice: the answer's cost (negative log-likelihood), whether the polish moved it, the score of
    the candidate it was refined from (``start_T_lidar_cam``, 4x4) and how many were refined, the range-noise std
    the search scored with (metres), and the refinement's cost and function evaluations."""

    cost: float
    polished: bool
    score_start: float
    n_refined: int
    start_T_lidar_cam: np.ndarray
    sigma_m_selection: float
    refine_cost: float
    refine_nfev: int

    def entries(self) -> dict:
        return {"cost": self.cost, "polished": self.polished, "score_start": self.score_start,
                "n_refined": self.n_refined, "start_T_lidar_cam": self.start_T_lidar_cam,
                "sigma_m_selection": self.sigma_m_selection, "refine_cost": self.refine_cost,
                "refine_nfev": self.refine_nfev}


@dataclass(frozen=True, eq=False)
class InfoParts:
    """Everything a method reports beside the extrinsic and its candidates, as parts (None or empty: no entry).

    Attributes:
        base: the base method's info of a derived method (``X+ml``, ``X+joint``): every other part overrides it.
        choice: ``lidarcam``'s choice (``ChoicePart``).
        consensus: the boards used and left out, the points trimmed, the search (``robust.final``'s report).
        refinement: a refinement's report (``refine.partial.refine_free``'s, or ``refine_cost`` and the like).
        prior: the mounting prior given (``methods.last_steps.prior_info``).
        covariance: the covariance with its model (``CovariancePart``).
        joint: the joint model's fit (``JointFitPart``).
        degeneracy: the directions the boards leave free (``checks.degeneracy.Degeneracy.to_dict``).
        alternatives: the answers nearly as likely as the answer (``methods.lidarcam.alternatives``).
        board_error: the per-board systematic error held (``refine.systematic.BoardErrorEstimate.to_dict``).
        noise_model: the noise model the covariance holds (``NoiseModel``).
        base_T_lidar_cam: a derived method's start, the base method's answer (4x4).
        warnings: the method's warnings (None: no entry, as for a method that gives none).
        residual_rms: the range residuals' RMS at the start and the answer (``ResidualRmsPart``; added by
            ``calibrate``, as the next two).
        verdict: the consistency verdict of the answer (``VerdictPart``).
        observations: which observations the answer was computed from (``ObservationsPart``).
    """

    base: dict = field(default_factory=dict)
    choice: ChoicePart | None = None
    consensus: dict = field(default_factory=dict)
    refinement: dict = field(default_factory=dict)
    prior: dict | None = None
    covariance: CovariancePart | None = None
    joint: JointFitPart | None = None
    degeneracy: dict | None = None
    alternatives: list | None = None
    board_error: dict | None = None
    noise_model: NoiseModel | None = None
    base_T_lidar_cam: np.ndarray | None = None
    warnings: list[str] | None = None
    residual_rms: ResidualRmsPart | None = None
    verdict: VerdictPart | None = None
    observations: ObservationsPart | None = None

    def to_info(self) -> dict:
        """The ``info`` dict of ``Method.func`` (what ``CalibrationResult.info`` and the ``lidarcam.result/1``
        file read): the one place the parts become entries."""
        info = dict(self.base)
        for part in (self.choice, self.covariance, self.joint):
            info.update(part.entries() if part is not None else {})
        info.update(self.consensus)
        info.update(self.refinement)
        single = {"prior": self.prior, "degeneracy": self.degeneracy, "alternatives": self.alternatives,
                  "board_error": self.board_error, "base_T_lidar_cam": self.base_T_lidar_cam,
                  "noise_model": None if self.noise_model is None else self.noise_model.to_dict(),
                  "residual_rms": None if self.residual_rms is None else self.residual_rms.to_dict(),
                  "verdict": None if self.verdict is None else self.verdict.to_dict(),
                  "warnings": None if self.warnings is None else list(self.warnings),
                  "observations": None if self.observations is None else self.observations.to_dict()}
        info.update({k: v for k, v in single.items() if v is not None})
        return info
