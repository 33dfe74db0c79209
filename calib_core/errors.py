"""Exception types of calib_core, all in one home: every bad-input error names its file, board and field; a method
that cannot solve raises ``SolveFailure`` with its reason, which ``calibrate`` turns into ``ok=False``."""

from __future__ import annotations

import numpy as np


class LidarcamError(Exception):
    """Base class of every error raised by lidarcam."""


class ObservationError(LidarcamError, ValueError):
    """Bad observation data: names the file, the board index and the field where known.

    ``str(err)`` reads ``"obs.json: board 3: field 'scan': fewer than 2 points"``.
    """

    def __init__(self, message: str, *, file: str | None = None, board: int | None = None,
                 field: str | None = None) -> None:
        self.message = message
        self.file = file
        self.board = board
        self.field = field
        super().__init__(self._render())

    def _render(self) -> str:
        parts = []
        if self.file is not None:
            parts.append(str(self.file))
        if self.board is not None:
            parts.append(f"board {self.board}")
        if self.field is not None:
            parts.append(f"field '{self.field}'")
        parts.append(self.message)
        return ": ".join(parts)

    def within(self, *, file: str | None = None, board: int | None = None) -> ObservationError:
        """The same error with the file and/or board filled in (kept where already set)."""
        return ObservationError(self.message, file=self.file if self.file is not None else file,
                                board=self.board if self.board is not None else board,
                                field=self.field)


class CalibrationError(LidarcamError):
    """A method was asked for something it cannot do (unknown method name, bad option)."""


class SolveFailure(LidarcamError):
    """Raised inside a method when it cannot solve; ``calibrate`` turns it into ``ok=False`` with the reason.

    ``candidates`` (M,4,4) are the candidates considered before failing, kept for the benchmark; ``info``
    diagnostics for the result (e.g. the directions a degenerate board set does not determine).
    """

    def __init__(self, reason: str, candidates: np.ndarray | None = None, info: dict | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.candidates = np.zeros((0, 4, 4)) if candidates is None else np.asarray(candidates, float)
        self.info = dict(info or {})


class UncertaintyError(LidarcamError):
    """The uncertainty cannot be computed: too few residuals, a singular information matrix, no extrinsic."""


class JointError(LidarcamError):
    """The joint model does not apply: no corners or no camera, or a board behind the camera."""
