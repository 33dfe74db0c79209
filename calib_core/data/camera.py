"""The camera's intrinsics and its projection through the OpenCV distortion model, with analytic Jacobians.

Frame ``{C}``: z optical axis, x right, y down; pixels follow OpenCV (pixel (i, j) centred at x = j, y = i).
Distortion coefficients in OpenCV order ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tx, ty]]]])``:
for ``x' = X/Z``, ``y' = Y/Z``, ``r^2 = x'^2 + y'^2``,

    x'' = x' a/b + 2 p1 x'y' + p2 (r^2 + 2 x'^2) + s1 r^2 + s2 r^4
    y'' = y' a/b + p1 (r^2 + 2 y'^2) + 2 p2 x'y' + s3 r^2 + s4 r^4,   u = fx x'' + cx,  v = fy y'' + cy

with ``a = 1 + k1 r^2 + k2 r^4 + k3 r^6`` and ``b = 1 + k4 r^2 + k5 r^4 + k6 r^6`` (``cv2.projectPoints``). The
tilted-sensor terms (tx, ty) must be zero. Units: metres and pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ObservationError

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector."""


def _fail(msg: str, field: str) -> ObservationError:
    return ObservationError(msg, field=f"camera.{field}")


@dataclass(frozen=True, eq=False)
class Camera:
    """Pinhole intrinsics with OpenCV distortion.

    Attributes:
        K: 3x3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (pixels; no skew: OpenCV's model has none).
        dist: distortion coefficients in OpenCV order (length 0, 4, 5, 8, 12 or 14), stored padded to 12.
        width, height: image size (pixels).
        std_intrinsics: optional 1-sigma of the intrinsics in OpenCV's order (``stdDeviationsIntrinsics`` of
            ``cv2.calibrateCameraExtended``): fx, fy, cx, cy (pixels), then the first coefficients of ``dist``
            (unitless); length 4 (distortion taken as exact) or 4 + the length of ``dist`` as given. None: the
            intrinsics are taken as exact.
    """

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    std_intrinsics: np.ndarray | None = None

    def __post_init__(self) -> None:
        try:
            K = np.array(self.K, dtype=float)
            dist = np.array(self.dist if self.dist is not None else [], dtype=float).ravel()
        except (TypeError, ValueError) as exc:
            raise _fail(f"not a numeric array ({exc})", "K") from None
        if K.shape != (3, 3):
            raise _fail(f"expected shape 3x3, got {'x'.join(map(str, K.shape)) or 'scalar'}", "K")
        if not np.all(np.isfinite(K)):
            raise _fail("contains NaN or inf", "K")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer, float)) or v != int(v) or int(v) < 1:
                raise _fail(f"must be a positive integer, got {v!r}", name)
            object.__setattr__(self, name, int(v))
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        if not (fx > 0 and fy > 0):
            raise _fail(f"focal lengths must be > 0, got fx={fx:g}, fy={fy:g}", "K")
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
            raise _fail("must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]", "K")
        if abs(K[0, 1]) > 1e-9 * fx:
            raise _fail(f"skew {K[0, 1]:g} is not zero (the OpenCV model has no skew)", "K")
        if not (0.2 < fx / fy < 5.0):
            raise _fail(f"implausible aspect ratio fx/fy = {fx / fy:.3g}", "K")
        if not (-0.5 <= cx <= self.width - 0.5 and -0.5 <= cy <= self.height - 0.5):
            raise _fail(f"principal point ({cx:g}, {cy:g}) outside the {self.width}x{self.height} image", "K")
        if len(dist) not in DIST_LENGTHS:
            raise _fail(f"length {len(dist)} is not an OpenCV distortion vector ({DIST_LENGTHS[1:]})", "dist")
        if not np.all(np.isfinite(dist)):
            raise _fail("contains NaN or inf", "dist")
        if len(dist) == 14 and np.any(dist[12:] != 0):
            raise _fail("tilted-sensor terms (tx, ty) are not supported; they must be 0", "dist")
        d12 = np.zeros(12)
        d12[:min(len(dist), 12)] = dist[:12]
        if self.std_intrinsics is not None:
            object.__setattr__(self, "std_intrinsics", _checked_std(self.std_intrinsics, len(dist),
                                                                    max(self.width, self.height)))
        K.setflags(write=False)
        d12.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", d12)

    def to_dict(self) -> dict:
        """Plain-JSON form: ``K``, ``dist`` (trailing zeros beyond the 5th coefficient dropped, or as long as
        ``std_intrinsics`` says), width, height, and ``std_intrinsics`` when given."""
        n = 5 if not np.any(self.dist[5:]) else (8 if not np.any(self.dist[8:]) else 12)
        d = {"K": self.K.tolist(), "dist": self.dist[:n].tolist(), "width": self.width, "height": self.height}
        if self.std_intrinsics is not None:
            n_std = len(self.std_intrinsics) - 4  # the dist length it was given with (validated on creation)
            d["dist"] = self.dist[:n_std].tolist() if n_std > 0 else d["dist"]
            d["std_intrinsics"] = self.std_intrinsics.tolist()
        return d

    @property
    def intrinsics(self) -> np.ndarray:
        """(4 + 12,) fx, fy, cx, cy (pixels) then the 12 distortion coefficients: ``std_intrinsics``' order."""
        return np.r_[self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.dist]

    def with_intrinsics(self, k: np.ndarray) -> Camera:
        """This camera with intrinsics ``k`` (``intrinsics`` order; a shorter vector leaves the rest as they are),
        without ``std_intrinsics`` (the 1-sigma of other values)."""
        v = self.intrinsics
        v[:len(k)] = k
        K = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
        return Camera(K, v[4:], self.width, self.height)


def _checked_std(std, n_dist: int, size_px: float) -> np.ndarray:
    """``std_intrinsics`` as a read-only float array; ObservationError naming the field when it is not a list of
    4 or 4 + ``n_dist`` finite non-negative numbers, or a pixel 1-sigma exceeds 1000 times the image's larger side
    ``size_px`` or a distortion coefficient's exceeds 1e4 (an intrinsic that uncertain is unknown, not a prior:
    its weight vanishes from the normal equations, which turn singular)."""
    try:
        s = np.array(std, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise _fail(f"not a numeric array ({exc})", "std_intrinsics") from None
    if len(s) not in (4, 4 + n_dist):
        raise _fail(f"length {len(s)}: expected 4 (fx fy cx cy) or {4 + n_dist} (with the {n_dist} coefficients "
                    "of dist)", "std_intrinsics")
    if not np.all(np.isfinite(s)):
        raise _fail("contains NaN or inf", "std_intrinsics")
    if np.any(s < 0):
        raise _fail(f"negative standard deviation {s.min():g}", "std_intrinsics")
    if np.any(s[:4] > 1000 * size_px):
        raise _fail(f"a 1-sigma of {s[:4].max():g} px exceeds 1000 times the image's {size_px:g} px: the "
                    "intrinsics would be unknown, not a prior", "std_intrinsics")
    if np.any(s[4:] > 1e4):
        raise _fail(f"a distortion coefficient's 1-sigma of {s[4:].max():g} exceeds 1e4: the distortion would be "
                    "unknown, not a prior", "std_intrinsics")
    s.setflags(write=False)
    return s


def _distort(dist: np.ndarray, x: np.ndarray, y: np.ndarray):
    """OpenCV's distortion (rational radial, tangential, thin prism) of normalised image points ``x``, ``y``:
    ``(r2, a, b, rad, xd, yd)`` with ``r2 = x^2 + y^2``, the radial numerator ``a`` and denominator ``b``,
    ``rad = a / b`` and the distorted normalised point ``(xd, yd)``."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = dist
    r2 = x * x + y * y
    a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = a / b
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + r2 * (s3 + s4 * r2)
    return r2, a, b, rad, xd, yd


def intrinsics_jacobian(camera: Camera, P_cam: np.ndarray) -> np.ndarray:
    """d(u, v)/d(fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4) (...,2,16) of ``project`` at
    camera-frame points ``P_cam`` (...,3) (metres): pixels per pixel for K, pixels per unit for the coefficients."""
    P = np.asarray(P_cam, float)
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    iz = 1.0 / P[..., 2]
    x, y = P[..., 0] * iz, P[..., 1] * iz
    r2, a, b, rad, xd, yd = _distort(camera.dist, x, y)
    z, one = np.zeros_like(x), np.ones_like(x)
    pw = np.stack([r2, r2**2, r2**3])                        # r^2, r^4, r^6
    drad = np.concatenate([pw / b, -pw * a / b**2])          # d rad / d(k1, k2, k3, k4, k5, k6)
    dx = [x * drad[0], x * drad[1], 2 * x * y, r2 + 2 * x * x, x * drad[2], x * drad[3], x * drad[4], x * drad[5],
          r2, r2**2, z, z]
    dy = [y * drad[0], y * drad[1], r2 + 2 * y * y, 2 * x * y, y * drad[2], y * drad[3], y * drad[4], y * drad[5],
          z, z, r2, r2**2]
    ru = [xd, z, one, z] + [fx * v for v in dx]
    rv = [z, yd, z, one] + [fy * v for v in dy]
    return np.stack([np.stack(ru, axis=-1), np.stack(rv, axis=-1)], axis=-2)


def project(camera: Camera, P_cam: np.ndarray, jacobian: bool = False):
    """Pixels (...,2) of camera-frame points ``P_cam`` (...,3) (metres) through the OpenCV model; with ``jacobian``
    also d(u, v)/d(X, Y, Z) (...,2,3). Points need Z > 0."""
    P = np.asarray(P_cam, float)
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = camera.dist
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    iz = 1.0 / P[..., 2]
    x, y = P[..., 0] * iz, P[..., 1] * iz
    r2, a, b, rad, xd, yd = _distort(camera.dist, x, y)
    uv = np.stack([fx * xd + camera.K[0, 2], fy * yd + camera.K[1, 2]], axis=-1)
    if not jacobian:
        return uv
    da = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    db = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    drad = (da * b - a * db) / b**2                 # d rad / d r^2
    gx = s1 + 2 * s2 * r2                           # d(s1 r^2 + s2 r^4) / d r^2
    gy = s3 + 2 * s4 * r2
    D = np.empty(P.shape[:-1] + (2, 2))             # d(x'', y'') / d(x', y')
    D[..., 0, 0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * x * gx
    D[..., 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * y * gx
    D[..., 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * x * gy
    D[..., 1, 1] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * y * gy
    N = np.zeros(P.shape[:-1] + (2, 3))             # d(x', y') / d(X, Y, Z)
    N[..., 0, 0] = iz
    N[..., 1, 1] = iz
    N[..., 0, 2] = -x * iz
    N[..., 1, 2] = -y * iz
    J = np.einsum("...ab,...bc->...ac", D, N)
    J[..., 0, :] *= fx
    J[..., 1, :] *= fy
    return uv, J
