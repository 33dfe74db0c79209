"""lidarcam's calibration library: data model, solvers, selection, refinement and metrics.

Frames: ``{L}`` lidar (scan plane z = 0), ``{C}`` camera, ``{W}_i`` board i. ``T_a_b`` maps points of
frame b into frame a; the unknown extrinsic is ``T_lidar_cam`` (the paper's ``p_L = R p_C + t``).
Units inside the library: metres and radians.
"""

from .data.io import extrinsic_yaml, load_observations, observations_from_dict, observations_to_dict, save_observations
from .data.observations import BoardObservation, Observations
from .errors import CalibrationError, LidarcamError, ObservationError, SolveFailure

__all__ = [
    "BoardObservation", "CalibrationError", "LidarcamError", "ObservationError", "Observations",
    "extrinsic_yaml", "load_observations", "observations_from_dict", "observations_to_dict", "save_observations",
]

from .data.result import CalibrationResult, load_result  # noqa: E402
from .entry import calibrate  # noqa: E402
from .methods import register_builtins  # noqa: E402
from .registry import METHODS, get_method  # noqa: E402

__all__ += ["METHODS", "CalibrationResult", "SolveFailure", "calibrate", "get_method", "load_result"]

register_builtins()
