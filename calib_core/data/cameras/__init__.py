"""The camera models, by Kalibr's names: ``(camera_model, distortion_model)`` -> model class.

``pinhole``/``radtan`` is ``calib_core.data.camera.Camera`` (OpenCV's model, rational and thin-prism terms kept);
``pinhole``/``equidistant`` Kannala-Brandt (``cv2.fisheye``); ``omni``/``radtan`` Mei's unified model; ``ds``/``none``
the double sphere; ``eucm``/``none`` the enhanced unified model. Every model offers ``CameraModel``'s interface.
"""

from __future__ import annotations

from ..camera import Camera, CameraModel
from .ds import DoubleSphere
from .equidistant import Equidistant
from .eucm import EUCM
from .omni import Omni

CAMERA_MODELS: dict[tuple[str, str], type] = {
    ("pinhole", "radtan"): Camera,
    ("pinhole", "equidistant"): Equidistant,
    ("omni", "radtan"): Omni,
    ("ds", "none"): DoubleSphere,
    ("eucm", "none"): EUCM,
}
"""Every camera model by Kalibr's ``(camera_model, distortion_model)``."""

MODEL_NAMES: dict[str, tuple[str, str]] = {(c if d == "none" else f"{c}-{d}"): (c, d) for c, d in CAMERA_MODELS}
"""The models' one-word names (``CameraModel.name``: ``pinhole-radtan``, ``pinhole-equidistant``, ``omni-radtan``,
``ds``, ``eucm``) -> Kalibr's pair."""


def camera_class(camera_model: str = "pinhole", distortion_model: str | None = None) -> type:
    """The class of Kalibr's ``camera_model`` and ``distortion_model`` (default: ``radtan`` for ``pinhole`` and
    ``omni``, ``none`` for ``ds`` and ``eucm``); ``camera_model`` may also be a one-word name of ``MODEL_NAMES``.
    KeyError naming the accepted values otherwise."""
    if distortion_model is None and camera_model in MODEL_NAMES:
        return CAMERA_MODELS[MODEL_NAMES[camera_model]]
    if distortion_model is None:
        distortion_model = "none" if camera_model in ("ds", "eucm") else "radtan"
    key = (camera_model, distortion_model)
    if key not in CAMERA_MODELS:
        raise KeyError(f"camera_model {camera_model!r} with distortion_model {distortion_model!r} is not a known "
                       f"model (known: {', '.join(f'{c}/{d}' for c, d in CAMERA_MODELS)})")
    return CAMERA_MODELS[key]


__all__ = ["CAMERA_MODELS", "MODEL_NAMES", "Camera", "CameraModel", "DoubleSphere", "EUCM", "Equidistant", "Omni",
           "camera_class"]
