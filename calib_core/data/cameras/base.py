"""What the camera models other than ``Camera`` (pinhole + OpenCV distortion) share: their fields' checks, the
intrinsics vector, its replacement and the plain-JSON form. Frame ``{C}``: z optical axis, x right, y down; metres
and pixels."""

from __future__ import annotations

import numpy as np

from ..camera import CameraModel, checked_core, checked_std, field_error


class FieldCamera(CameraModel):
    """Base of the frozen-dataclass models with fields ``K, dist, width, height, std_intrinsics`` then
    ``param_names``. A subclass sets ``dist_lengths`` (accepted lengths of ``dist``; stored padded to the longest),
    and ``check_params`` (raises on a value its model cannot take)."""

    dist_lengths: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        K = checked_core(self)
        try:
            dist = np.array(self.dist if self.dist is not None else [], dtype=float).ravel()
            params = [float(getattr(self, n)) for n in self.param_names]
        except (TypeError, ValueError) as exc:
            raise field_error(f"not a number ({exc})", "dist") from None
        if len(dist) not in self.dist_lengths:
            lengths = " or ".join(map(str, self.dist_lengths))
            raise field_error(f"length {len(dist)}: the {self.name} model takes {lengths} distortion coefficients",
                              "dist")
        if not np.all(np.isfinite(dist)):
            raise field_error("contains NaN or inf", "dist")
        for n, v in zip(self.param_names, params, strict=True):
            if not np.isfinite(v):
                raise field_error("is NaN or inf", n)
            object.__setattr__(self, n, v)
        self.check_params()
        full = np.zeros(max(self.dist_lengths))
        full[:len(dist)] = dist
        if self.std_intrinsics is not None:
            object.__setattr__(self, "std_intrinsics", checked_std(self.std_intrinsics, len(dist), self.n_core,
                                                                   max(self.width, self.height)))
        K.setflags(write=False)
        full.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", full)

    def check_params(self) -> None:
        """Raise ObservationError naming the parameter when the model cannot take its value."""

    @property
    def intrinsics(self) -> np.ndarray:
        """fx, fy, cx, cy (pixels), ``param_names``, then ``dist``: ``std_intrinsics``' order."""
        return np.r_[self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.params, self.dist]

    @property
    def intrinsic_names(self) -> tuple[str, ...]:
        """Names of ``intrinsics``' entries."""
        return ("fx", "fy", "cx", "cy") + self.param_names + tuple(f"d{i}" for i in range(len(self.dist)))

    def with_intrinsics(self, k: np.ndarray):
        """This camera with intrinsics ``k`` (``intrinsics`` order; a shorter vector leaves the rest as they are),
        without ``std_intrinsics``."""
        v = self.intrinsics
        v[:len(k)] = k
        K = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
        p = dict(zip(self.param_names, v[4:self.n_core], strict=True))
        return type(self)(K, v[self.n_core:], self.width, self.height, **p)

    def to_dict(self) -> dict:
        """Plain-JSON form: Kalibr's ``camera_model`` and ``distortion_model``, ``K``, ``dist`` (the shortest accepted
        length that keeps its non-zero values and ``std_intrinsics``' length), width, height, the model's parameters
        and ``std_intrinsics`` when given."""
        used = max(np.flatnonzero(self.dist), default=-1) + 1
        if self.std_intrinsics is not None:
            used = max(used, len(self.std_intrinsics) - self.n_core)
        n = min(k for k in self.dist_lengths if k >= used)
        d = {"camera_model": self.camera_model, "distortion_model": self.distortion_model, "K": self.K.tolist(),
             "dist": self.dist[:n].tolist(), "width": self.width, "height": self.height}
        d.update({n: float(getattr(self, n)) for n in self.param_names})
        if self.std_intrinsics is not None:
            d["std_intrinsics"] = self.std_intrinsics.tolist()
        return d

    def _uv(self, m: np.ndarray) -> np.ndarray:
        """Pixels of image-plane points ``m`` (...,2)."""
        return np.stack([self.K[0, 0] * m[..., 0] + self.K[0, 2], self.K[1, 1] * m[..., 1] + self.K[1, 2]], axis=-1)

    def _m(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image-plane points (mx, my) of pixels ``uv`` (...,2)."""
        q = np.asarray(uv, float)
        return (q[..., 0] - self.K[0, 2]) / self.K[0, 0], (q[..., 1] - self.K[1, 2]) / self.K[1, 1]

    def _k_jacobian(self, m: np.ndarray, dm_dp: list) -> np.ndarray:
        """d(u, v)/d(intrinsics) (...,2,n) from image-plane points ``m`` (...,2) and the list of d m/d(each
        parameter after cx, cy) (...,2)."""
        z, one = np.zeros(m.shape[:-1]), np.ones(m.shape[:-1])
        f = np.array([self.K[0, 0], self.K[1, 1]])
        cols = [np.stack([m[..., 0], z], -1), np.stack([z, m[..., 1]], -1), np.stack([one, z], -1),
                np.stack([z, one], -1)] + [f * d for d in dm_dp]
        return np.stack(cols, axis=-1)
