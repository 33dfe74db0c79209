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
from typing import ClassVar

import numpy as np

from ..errors import ObservationError

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector."""


def field_error(msg: str, field: str) -> ObservationError:
    """The one-line error of a camera's ``field`` (named ``camera.<field>``, as the observation file spells it),
    saying ``msg``; every camera model's checks raise it."""
    return ObservationError(msg, field=f"camera.{field}")


class CameraModel:
    """What every camera model offers (Kalibr's names: ``camera_model`` and ``distortion_model``); the models are
    frozen dataclasses with the fields ``K`` (3x3: fx, fy, cx, cy in pixels), ``dist``, ``width``, ``height`` and
    ``std_intrinsics``, then their own parameters (``param_names``) as keywords.

    ``intrinsics`` orders fx, fy, cx, cy (pixels), the model's parameters, then the distortion coefficients; ``project``
    maps camera-frame points (...,3) (metres, frame ``{C}``) to pixels (...,2) (with ``jacobian`` also
    d(u, v)/d(X, Y, Z) (...,2,3)); ``intrinsics_jacobian`` is d(u, v)/d(intrinsics) (...,2,n); ``valid`` says
    which points the model projects (one-to-one; the others are refused, their pixels meaningless); ``unproject``
    maps pixels to unit rays (...,3) and a mask of the pixels that have one."""

    camera_model: ClassVar[str] = "pinhole"
    distortion_model: ClassVar[str] = "radtan"
    param_names: ClassVar[tuple[str, ...]] = ()

    @property
    def name(self) -> str:
        """``camera_model-distortion_model``, or the camera model alone when it has no distortion."""
        none = self.distortion_model == "none"
        return self.camera_model if none else f"{self.camera_model}-{self.distortion_model}"

    @property
    def params(self) -> np.ndarray:
        """The model's own parameters (``param_names`` order)."""
        return np.array([getattr(self, n) for n in self.param_names], float)

    @property
    def n_core(self) -> int:
        """Number of intrinsics before the distortion coefficients (fx, fy, cx, cy and ``param_names``)."""
        return 4 + len(self.param_names)


@dataclass(frozen=True, eq=False)
class Camera(CameraModel):
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
        K = checked_core(self)
        try:
            dist = np.array(self.dist if self.dist is not None else [], dtype=float).ravel()
        except (TypeError, ValueError) as exc:
            raise field_error(f"not a numeric array ({exc})", "dist") from None
        if len(dist) not in DIST_LENGTHS:
            raise field_error(f"length {len(dist)} is not an OpenCV distortion vector ({DIST_LENGTHS[1:]})", "dist")
        if not np.all(np.isfinite(dist)):
            raise field_error("contains NaN or inf", "dist")
        if len(dist) == 14 and np.any(dist[12:] != 0):
            raise field_error("tilted-sensor terms (tx, ty) are not supported; they must be 0", "dist")
        d12 = np.zeros(12)
        d12[:min(len(dist), 12)] = dist[:12]
        if self.std_intrinsics is not None:
            object.__setattr__(self, "std_intrinsics", checked_std(self.std_intrinsics, len(dist),
                                                                   size_px=max(self.width, self.height)))
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

    @property
    def intrinsic_names(self) -> tuple[str, ...]:
        """Names of ``intrinsics``' entries."""
        return ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4")

    def with_intrinsics(self, k: np.ndarray) -> Camera:
        """This camera with intrinsics ``k`` (``intrinsics`` order; a shorter vector leaves the rest as they are),
        without ``std_intrinsics`` (the 1-sigma of other values)."""
        v = self.intrinsics
        v[:len(k)] = k
        K = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
        return Camera(K, v[4:], self.width, self.height)

    def project(self, P_cam: np.ndarray, jacobian: bool = False):
        """``project`` (module function) through this camera."""
        return _radtan_project(self, P_cam, jacobian)

    def intrinsics_jacobian(self, P_cam: np.ndarray) -> np.ndarray:
        """``intrinsics_jacobian`` (module function) of this camera, (...,2,16)."""
        return _radtan_intrinsics_jacobian(self, P_cam)

    def valid(self, P_cam: np.ndarray) -> np.ndarray:
        """Points (...,3) in front of the camera (Z > 0) whose normalised radius lies inside the distortion's fold."""
        P = np.asarray(P_cam, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.hypot(P[..., 0], P[..., 1]) / P[..., 2]
            return (P[..., 2] > 0) & (r < fold_radius_cached(self))

    def unproject(self, uv: np.ndarray):
        """Unit rays (...,3) of pixels ``uv`` (...,2) and the mask of those with one (undistortion converged
        inside the fold)."""
        q = np.asarray(uv, float)
        x, y, ok = undistort(self.dist, (q[..., 0] - self.K[0, 2]) / self.K[0, 0],
                             (q[..., 1] - self.K[1, 2]) / self.K[1, 1])
        ray = np.stack([x, y, np.ones_like(x)], axis=-1)
        ok &= np.hypot(x, y) < fold_radius_cached(self)
        return ray / np.linalg.norm(ray, axis=-1, keepdims=True), ok


def fold_radius_cached(cam) -> float:
    """``fold_radius`` of ``cam.dist`` (a normalised image radius, unitless: metres over metres in the camera frame),
    computed once per camera and kept on it."""
    if "_fold" not in cam.__dict__:
        object.__setattr__(cam, "_fold", fold_radius(cam.dist))
    return cam.__dict__["_fold"]


_CORE_EXTRA = {5: ("xi",), 6: ("the model's two parameters",)}


def checked_core(cam) -> np.ndarray:
    """``cam.K`` (pixels) checked (3x3, finite, positive focal lengths, no skew, plausible aspect, principal point
    on the image) as a float array; ``cam.width`` and ``cam.height`` (pixels) checked and set to ints.
    ObservationError naming the field otherwise."""
    try:
        K = np.array(cam.K, dtype=float)
        np.array(cam.dist if cam.dist is not None else [], dtype=float)
    except (TypeError, ValueError) as exc:
        raise field_error(f"not a numeric array ({exc})", "K") from None
    if K.shape != (3, 3):
        raise field_error(f"expected shape 3x3, got {'x'.join(map(str, K.shape)) or 'scalar'}", "K")
    if not np.all(np.isfinite(K)):
        raise field_error("contains NaN or inf", "K")
    for name in ("width", "height"):
        v = getattr(cam, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer, float)) or v != int(v) or int(v) < 1:
            raise field_error(f"must be a positive integer, got {v!r}", name)
        object.__setattr__(cam, name, int(v))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0):
        raise field_error(f"focal lengths must be > 0, got fx={fx:g}, fy={fy:g}", "K")
    if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise field_error("must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]", "K")
    if abs(K[0, 1]) > 1e-9 * fx:
        raise field_error(f"skew {K[0, 1]:g} is not zero (the OpenCV model has no skew)", "K")
    if not (0.2 < fx / fy < 5.0):
        raise field_error(f"implausible aspect ratio fx/fy = {fx / fy:.3g}", "K")
    if not (-0.5 <= cx <= cam.width - 0.5 and -0.5 <= cy <= cam.height - 0.5):
        raise field_error(f"principal point ({cx:g}, {cy:g}) outside the {cam.width}x{cam.height} image", "K")
    return K


def checked_std(std, n_dist: int, n_core: int = 4, size_px: float | None = None) -> np.ndarray:
    """``std_intrinsics`` (1-sigma: fx fy cx cy in pixels, then the model's parameters and distortion coefficients
    in their own units) as a read-only float array; ObservationError naming the field when it is not a list of
    ``n_core`` or ``n_core`` + ``n_dist`` finite non-negative numbers, or (given ``size_px``, the image's larger
    side) a 1-sigma of fx fy cx cy exceeds 1000 times it or another 1-sigma exceeds 1e4: an intrinsic that
    uncertain is unknown, not a prior (its weight vanishes from the normal equations, which turn singular)."""
    try:
        s = np.array(std, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise field_error(f"not a numeric array ({exc})", "std_intrinsics") from None
    if len(s) not in (n_core, n_core + n_dist):
        core = "fx fy cx cy" + "".join(f" {n}" for n in _CORE_EXTRA.get(n_core, ()))
        raise field_error(f"length {len(s)}: expected {n_core} ({core}) or {n_core + n_dist} (with the {n_dist} "
                          "coefficients of dist)", "std_intrinsics")
    if not np.all(np.isfinite(s)):
        raise field_error("contains NaN or inf", "std_intrinsics")
    if np.any(s < 0):
        raise field_error(f"negative standard deviation {s.min():g}", "std_intrinsics")
    if size_px is not None and np.any(s[:4] > 1000 * size_px):
        raise field_error(f"a 1-sigma of {s[:4].max():g} px exceeds 1000 times the image's {size_px:g} px: the "
                          "intrinsics would be unknown, not a prior", "std_intrinsics")
    if size_px is not None and np.any(s[4:] > 1e4):
        raise field_error(f"a distortion coefficient's 1-sigma of {s[4:].max():g} exceeds 1e4: the distortion would be "
                          "unknown, not a prior", "std_intrinsics")
    s.setflags(write=False)
    return s


def opencv_distort(dist: np.ndarray, x: np.ndarray, y: np.ndarray):
    """OpenCV's distortion (rational radial, tangential, thin prism; ``dist`` its 12 coefficients) of normalised
    image points ``x``, ``y`` (unitless: the camera-frame point over its depth):
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


def opencv_distort_jacobian(dist: np.ndarray, x: np.ndarray, y: np.ndarray, r2, a, b, rad) -> np.ndarray:
    """d(x'', y'')/d(x', y') (...,2,2) of OpenCV's distortion at normalised points ``x``, ``y`` (``opencv_distort``'s
    ``r2, a, b, rad`` there)."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = dist
    da = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    db = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    drad = (da * b - a * db) / b**2                 # d rad / d r^2
    gx = s1 + 2 * s2 * r2                           # d(s1 r^2 + s2 r^4) / d r^2
    gy = s3 + 2 * s4 * r2
    D = np.empty(np.shape(x) + (2, 2))
    D[..., 0, 0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * x * gx
    D[..., 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * y * gx
    D[..., 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * x * gy
    D[..., 1, 1] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * y * gy
    return D


def opencv_distort_params_jacobian(x, y, r2, a, b):
    """d(x'', y'')/d(k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4) at normalised points ``x``, ``y`` (unitless;
    ``opencv_distort``'s ``r2, a, b`` there): two lists of 12 arrays (x'' then y'')."""
    z = np.zeros_like(x)
    pw = np.stack([r2, r2**2, r2**3])                        # r^2, r^4, r^6
    drad = np.concatenate([pw / b, -pw * a / b**2])          # d rad / d(k1, k2, k3, k4, k5, k6)
    dx = [x * drad[0], x * drad[1], 2 * x * y, r2 + 2 * x * x, x * drad[2], x * drad[3], x * drad[4], x * drad[5],
          r2, r2**2, z, z]
    dy = [y * drad[0], y * drad[1], r2 + 2 * y * y, 2 * x * y, y * drad[2], y * drad[3], y * drad[4], y * drad[5],
          z, z, r2, r2**2]
    return dx, dy


def fold_radius(dist: np.ndarray, r_max: float = 20.0) -> float:
    """The normalised radius (``r = |(x', y')|``) where OpenCV's radial map ``r a/b`` first stops increasing (or its
    denominator ``b`` first reaches 0), searched on ``[0, r_max]``: beyond it the model is not one-to-one. ``r_max``
    when it increases throughout."""
    r = np.linspace(0.0, r_max, 20001)[1:]
    _, a, b, rad, xd, _ = opencv_distort(np.asarray(dist, float), r, np.zeros_like(r))
    bad = np.flatnonzero((np.diff(np.r_[0.0, xd]) <= 0) | (b <= 0))
    return float(r[bad[0] - 1]) if len(bad) and bad[0] > 0 else (0.0 if len(bad) else r_max)


def undistort(dist: np.ndarray, xd: np.ndarray, yd: np.ndarray, iterations: int = 30):
    """Normalised points ``(x', y')`` whose OpenCV distortion is ``(xd, yd)``, by Newton's method from the distorted
    point's radial inverse (bisection inside ``fold_radius``); with the mask of those that converged (residual
    below 1e-10)."""
    xd, yd = np.asarray(xd, float), np.asarray(yd, float)
    rd = np.hypot(xd, yd)
    lo, hi = np.zeros_like(rd), np.full_like(rd, fold_radius(dist))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = opencv_distort(dist, mid, np.zeros_like(mid))[4] < rd
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    k = np.where(rd > 0, lo / np.where(rd > 0, rd, 1.0), 1.0)
    x, y = k * xd, k * yd
    with np.errstate(all="ignore"):
        return _newton(dist, x, y, xd, yd, iterations)


def _newton(dist, x, y, xd, yd, iterations):
    for _ in range(iterations):
        r2, a, b, rad, ex, ey = opencv_distort(dist, x, y)
        ex, ey = ex - xd, ey - yd
        D = opencv_distort_jacobian(dist, x, y, r2, a, b, rad)
        det = D[..., 0, 0] * D[..., 1, 1] - D[..., 0, 1] * D[..., 1, 0]
        det = np.where(np.abs(det) > 1e-12, det, 1e-12)
        sx, sy = (D[..., 1, 1] * ex - D[..., 0, 1] * ey) / det, (-D[..., 1, 0] * ex + D[..., 0, 0] * ey) / det
        x, y = x - sx, y - sy
        if np.nanmax(np.abs(np.r_[np.ravel(sx), np.ravel(sy)]), initial=0.0) < 1e-15:
            break
    _, _, _, _, ex, ey = opencv_distort(dist, x, y)
    ok = np.hypot(ex - xd, ey - yd) < 1e-10
    return x, y, ok & np.isfinite(x) & np.isfinite(y)


def view_depth(camera: CameraModel | None, P_cam: np.ndarray) -> np.ndarray:
    """How far in front of ``camera`` points ``P_cam`` (...,3) lie, as the plausibility tests read it (metres):
    Z for the pinhole ``Camera`` or no camera; for a wide-angle model, which sees beside and behind its axis, the
    distance ``|P|`` where the model takes the point (``valid``) and ``-|P|`` where it does not."""
    P = np.asarray(P_cam, float)
    if camera is None or isinstance(camera, Camera):
        return P[..., 2]
    d = np.linalg.norm(P, axis=-1)
    return np.where(camera.valid(P), d, -d)


def intrinsics_jacobian(camera: CameraModel, P_cam: np.ndarray) -> np.ndarray:
    """d(u, v)/d(``camera.intrinsics``) (...,2,n) of ``project`` at camera-frame points ``P_cam`` (...,3) (metres):
    pixels per pixel for fx, fy, cx, cy, pixels per unit for the others. For ``Camera`` the order is (fx, fy, cx,
    cy, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4)."""
    return camera.intrinsics_jacobian(P_cam)


def project(camera: CameraModel, P_cam: np.ndarray, jacobian: bool = False):
    """Pixels (...,2) of camera-frame points ``P_cam`` (...,3) (metres) through ``camera``'s model; with ``jacobian``
    also d(u, v)/d(X, Y, Z) (...,2,3). Only the points ``camera.valid`` accepts have meaningful pixels (for
    ``Camera``: Z > 0 inside the distortion's fold)."""
    return camera.project(P_cam, jacobian)


def _radtan_intrinsics_jacobian(camera: Camera, P_cam: np.ndarray) -> np.ndarray:
    P = np.asarray(P_cam, float)
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    iz = 1.0 / P[..., 2]
    x, y = P[..., 0] * iz, P[..., 1] * iz
    r2, a, b, rad, xd, yd = opencv_distort(camera.dist, x, y)
    z, one = np.zeros_like(x), np.ones_like(x)
    dx, dy = opencv_distort_params_jacobian(x, y, r2, a, b)
    ru = [xd, z, one, z] + [fx * v for v in dx]
    rv = [z, yd, z, one] + [fy * v for v in dy]
    return np.stack([np.stack(ru, axis=-1), np.stack(rv, axis=-1)], axis=-2)


def _radtan_project(camera: Camera, P_cam: np.ndarray, jacobian: bool = False):
    P = np.asarray(P_cam, float)
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    iz = 1.0 / P[..., 2]
    x, y = P[..., 0] * iz, P[..., 1] * iz
    r2, a, b, rad, xd, yd = opencv_distort(camera.dist, x, y)
    uv = np.stack([fx * xd + camera.K[0, 2], fy * yd + camera.K[1, 2]], axis=-1)
    if not jacobian:
        return uv
    D = opencv_distort_jacobian(camera.dist, x, y, r2, a, b, rad)  # d(x'', y'') / d(x', y')
    N = np.zeros(P.shape[:-1] + (2, 3))             # d(x', y') / d(X, Y, Z)
    N[..., 0, 0] = iz
    N[..., 1, 1] = iz
    N[..., 0, 2] = -x * iz
    N[..., 1, 2] = -y * iz
    J = np.einsum("...ab,...bc->...ac", D, N)
    J[..., 0, :] *= fx
    J[..., 1, :] *= fy
    return uv, J
