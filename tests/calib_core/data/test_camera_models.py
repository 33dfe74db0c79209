"""The camera models (calib_core.data.cameras): analytic Jacobians against finite differences on many seeded
instances, project/unproject round trips over the whole image and beyond 90 deg, OpenCV's own projections, each
paper's formulas written out here independently, and the points and pixels each model refuses."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from calib_core.data.cameras import (
    CAMERA_MODELS,
    EUCM,
    MODEL_NAMES,
    Camera,
    DoubleSphere,
    Equidistant,
    Omni,
    camera_class,
)
from calib_core.errors import ObservationError

W, H = 1280, 960


def _K(rng, f=None):
    f = rng.uniform(250, 450) if f is None else f
    return np.array([[f, 0, W / 2 + rng.uniform(-20, 20)], [0, f * rng.uniform(0.97, 1.03), H / 2 +
                     rng.uniform(-20, 20)], [0, 0, 1]])


def random_camera(name: str, rng) -> object:
    """A plausible camera of the model ``name`` (wide-angle for the fisheye models) whose domain covers the whole
    image."""
    if name == "pinhole-radtan":
        d = np.r_[rng.uniform(-0.1, -0.03), rng.uniform(0, 0.05), rng.normal(0, 1e-3, 2), rng.uniform(0, 0.01),
                  rng.uniform(0, 0.005, 3), rng.normal(0, 1e-3, 4)]
        return Camera(_K(rng, rng.uniform(700, 1000)), d, W, H)
    if name == "pinhole-equidistant":
        d = np.r_[rng.uniform(-0.02, 0.02), rng.uniform(-1e-3, 1e-3), rng.uniform(-1e-4, 1e-4),
                  rng.uniform(-1e-5, 1e-5)]
        return Equidistant(_K(rng, rng.uniform(350, 450)), d, W, H)
    if name == "omni-radtan":
        d = np.r_[rng.uniform(-0.1, 0.0), rng.uniform(0, 0.02), rng.normal(0, 1e-3, 2)]
        return Omni(_K(rng, rng.uniform(900, 1100)), d, W, H, xi=rng.uniform(0.5, 1.3))
    if name == "ds":
        return DoubleSphere(_K(rng, rng.uniform(450, 550)), [], W, H, xi=rng.uniform(-0.3, 0.3),
                            alpha=rng.uniform(0.4, 0.65))
    return EUCM(_K(rng, rng.uniform(520, 600)), [], W, H, alpha=rng.uniform(0.4, 0.65), beta=rng.uniform(0.8, 1.3))


NAMES = list(MODEL_NAMES)
WIDE = {"pinhole-radtan": 50, "pinhole-equidistant": 100, "omni-radtan": 100, "ds": 100, "eucm": 100}
"""Largest angle from the optical axis (deg) each test draws points at."""


def _points(rng, n, max_deg, near=0.3, far=5.0):
    th = np.radians(rng.uniform(0, max_deg, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    return rng.uniform(near, far, n)[:, None] * np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph),
                                                         np.cos(th)], 1)


@pytest.mark.parametrize("name", NAMES)
def test_point_and_intrinsics_jacobians_match_finite_differences(name):
    rng = np.random.default_rng(7)
    for _ in range(20):
        cam = random_camera(name, rng)
        P = _points(rng, 40, WIDE[name])
        P = P[cam.valid(P)]
        assert len(P) > 30
        uv, J = cam.project(P, jacobian=True)
        h = 1e-6
        Jn = np.stack([(cam.project(P + h * e) - cam.project(P - h * e)) / (2 * h) for e in np.eye(3)], -1)
        np.testing.assert_allclose(J, Jn, rtol=1e-5, atol=1e-4 * np.abs(Jn).max())
        k = cam.intrinsics
        Jk = cam.intrinsics_jacobian(P)
        assert Jk.shape == (len(P), 2, len(k))
        for i in range(len(k)):
            step = 1e-6 * max(1.0, abs(k[i]))
            kp, km = k.copy(), k.copy()
            kp[i] += step
            km[i] -= step
            num = (cam.with_intrinsics(kp).project(P) - cam.with_intrinsics(km).project(P)) / (2 * step)
            np.testing.assert_allclose(Jk[..., i], num, rtol=1e-5, atol=1e-5 * max(1.0, np.abs(num).max()))


def test_jacobian_on_the_optical_axis():
    rng = np.random.default_rng(3)
    for name in NAMES:
        cam = random_camera(name, rng)
        P = np.array([[0.0, 0.0, 2.0]])
        uv, J = cam.project(P, jacobian=True)
        np.testing.assert_allclose(uv, cam.K[:2, 2][None], atol=1e-9)
        assert np.all(np.isfinite(J)) and np.all(np.isfinite(cam.intrinsics_jacobian(P)))
        h = 1e-6
        Jn = np.stack([(cam.project(P + h * e) - cam.project(P - h * e)) / (2 * h) for e in np.eye(3)], -1)
        np.testing.assert_allclose(J, Jn, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_every_pixel_of_the_image_unprojects_and_projects_back(name):
    rng = np.random.default_rng(11)
    u, v = np.meshgrid(np.linspace(0, W - 1, 41), np.linspace(0, H - 1, 31))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    for _ in range(10):
        cam = random_camera(name, rng)
        rays, ok = cam.unproject(uv)
        assert ok.all(), f"{name}: {int((~ok).sum())} image pixels without a ray"
        np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-12)
        assert cam.valid(3.0 * rays).all()
        np.testing.assert_allclose(cam.project(3.0 * rays), uv, atol=1e-6)


@pytest.mark.parametrize("name", ["pinhole-equidistant", "omni-radtan", "ds", "eucm"])
def test_rays_beyond_90_degrees_round_trip(name):
    rng = np.random.default_rng(5)
    for _ in range(10):
        cam = random_camera(name, rng)
        P = _points(rng, 400, WIDE[name])
        ok = cam.valid(P)
        assert (np.degrees(np.arccos(P[ok, 2] / np.linalg.norm(P[ok], axis=1))) > 90).any()
        rays, back = cam.unproject(cam.project(P[ok]))
        assert back.all()
        np.testing.assert_allclose(rays, P[ok] / np.linalg.norm(P[ok], axis=1, keepdims=True), atol=1e-9)


def test_pinhole_radtan_equals_cv2_project_points():
    rng = np.random.default_rng(2)
    for _ in range(20):
        cam = random_camera("pinhole-radtan", rng)
        P = _points(rng, 50, 40)
        ref, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), cam.K, cam.dist)
        np.testing.assert_allclose(cam.project(P), ref.reshape(-1, 2), atol=1e-8)


def test_equidistant_equals_cv2_fisheye_project_points():
    rng = np.random.default_rng(4)
    for _ in range(20):
        cam = random_camera("pinhole-equidistant", rng)
        P = _points(rng, 50, 85)
        ref, _ = cv2.fisheye.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
        np.testing.assert_allclose(cam.project(P), ref.reshape(-1, 2), atol=1e-8)
        und = cv2.fisheye.undistortPoints(cam.project(P).reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
        rays, _ = cam.unproject(cam.project(P))
        np.testing.assert_allclose(rays[:, :2] / rays[:, 2:], und, atol=1e-6)


K0 = np.array([[300.0, 0, 640], [0, 310.0, 480], [0, 0, 1]])


def _paper(name, p, X, Y, Z):
    """Each paper's projection written out for one point, scalar by scalar (normalised image coordinates)."""
    if name == "ds":                                    # Usenko et al. 2018, eq. (40)-(43)
        xi, al = p
        d1 = math.sqrt(X * X + Y * Y + Z * Z)
        d2 = math.sqrt(X * X + Y * Y + (xi * d1 + Z) ** 2)
        den = al * d2 + (1 - al) * (xi * d1 + Z)
    elif name == "eucm":                                # Khomutenko et al. 2016, eq. (2)-(3)
        al, be = p
        den = al * math.sqrt(be * (X * X + Y * Y) + Z * Z) + (1 - al) * Z
    elif name == "omni":                                # Mei and Rives 2007: sphere, then pinhole xi behind
        (xi,) = p
        n = math.sqrt(X * X + Y * Y + Z * Z)
        den = Z / n + xi
        X, Y = X / n, Y / n
    else:                                               # Kannala and Brandt 2006, four terms
        th = math.atan2(math.hypot(X, Y), Z)
        k1, k2, k3, k4 = p
        thd = th + k1 * th**3 + k2 * th**5 + k3 * th**7 + k4 * th**9
        return thd * X / math.hypot(X, Y), thd * Y / math.hypot(X, Y)
    return X / den, Y / den


@pytest.mark.parametrize("cam, key, p", [
    (DoubleSphere(K0, [], W, H, xi=-0.25, alpha=0.58), "ds", (-0.25, 0.58)),
    (EUCM(K0, [], W, H, alpha=0.62, beta=1.15), "eucm", (0.62, 1.15)),
    (Omni(K0, [], W, H, xi=0.9), "omni", (0.9,)),
    (Equidistant(K0, [0.03, -0.01, 0.002, -1e-4], W, H), "kb", (0.03, -0.01, 0.002, -1e-4)),
])
def test_each_model_against_its_papers_formula(cam, key, p):
    pts = [(0.3, -0.2, 1.0), (1.0, 0.0, 0.0), (-0.5, 2.0, 0.4), (0.7, 0.7, -0.2), (0.01, 0.02, 3.0)]
    for X, Y, Z in pts:
        mx, my = _paper(key, p, X, Y, Z)
        assert cam.valid(np.array([X, Y, Z]))
        np.testing.assert_allclose(cam.project(np.array([X, Y, Z])), [300 * mx + 640, 310 * my + 480], rtol=1e-12)


def test_hand_checked_values():
    # a point at 90 deg: EUCM with alpha = 0.5, beta = 1 is the unified model with xi = 1, mx = X / (alpha d) = 2
    np.testing.assert_allclose(EUCM(K0, [], W, H, alpha=0.5).project(np.array([1.0, 0, 0])), [640 + 600, 480])
    # Mei with xi = 1 is the stereographic projection: 90 deg lands at m = 1
    np.testing.assert_allclose(Omni(K0, [], W, H, xi=1.0).project(np.array([0, 2.0, 0])), [640, 480 + 310])
    # equidistant without distortion: radius = fx theta
    np.testing.assert_allclose(Equidistant(K0, [], W, H).project(np.array([-1.0, 0, 0])), [640 - 300 * np.pi / 2, 480])
    # double sphere with xi = 0, alpha = 0 and the unified ones with xi = 0, alpha = 0 are the pinhole
    P = np.array([[0.2, -0.1, 1.5]])
    for cam in (DoubleSphere(K0, [], W, H), EUCM(K0, [], W, H), Omni(K0, [], W, H), Equidistant(K0, [], W, H)):
        pin = Camera(K0, [], W, H).project(P)
        if isinstance(cam, Equidistant):
            continue
        np.testing.assert_allclose(cam.project(P), pin, atol=1e-12)


def test_points_and_pixels_a_model_cannot_take_are_refused():
    # pinhole: behind the camera
    assert not Camera(K0, [], W, H).valid(np.array([0.1, 0, -1.0]))
    # pinhole with a strong barrel: beyond the radial fold (r (1 + k1 r^2) peaks at r = 1/sqrt(3 * 0.4))
    cam = Camera(K0, [-0.4, 0, 0, 0], W, H)
    assert cam.valid(np.array([0.85, 0, 1.0])) and not cam.valid(np.array([0.95, 0, 1.0]))
    # equidistant whose theta_d turns back at some angle below 180 deg
    eq = Equidistant(K0, [-0.2, 0, 0, 0], W, H)
    assert eq.theta_max == pytest.approx(1 / math.sqrt(0.6), abs=1e-3)
    assert not eq.valid(np.array([math.sin(1.3), 0, math.cos(1.3)]))
    assert not Equidistant(K0, [], W, H).valid(np.array([0.0, 0.0, -1.0]))     # the back pole
    # double sphere: beyond z > -w2 d1; pixels outside the image circle have no ray
    ds = DoubleSphere(K0, [], W, H, xi=-0.2, alpha=0.6)
    w1 = 0.4 / 0.6
    w2 = (w1 - 0.2) / math.sqrt(2 * w1 * -0.2 + 0.04 + 1)
    t = math.acos(-w2)
    assert ds.valid(np.array([math.sin(t - 0.01), 0, math.cos(t - 0.01)]))
    assert not ds.valid(np.array([math.sin(t + 0.01), 0, math.cos(t + 0.01)]))
    r_max = 1 / math.sqrt(2 * 0.6 - 1)
    _, ok = ds.unproject(np.array([[640 + 300 * r_max * 0.99, 480], [640 + 300 * r_max * 1.01, 480]]))
    assert ok.tolist() == [True, False]
    # EUCM and Mei beyond their domains
    eu = EUCM(K0, [], W, H, alpha=0.7, beta=1.0)
    assert not eu.valid(np.array([1.0, 0, -0.5])) and eu.valid(np.array([1.0, 0, -0.4]))
    om = Omni(K0, [], W, H, xi=2.0)
    assert not om.valid(np.array([1.0, 0, -0.6])) and om.valid(np.array([1.0, 0, -0.55]))
    _, ok = om.unproject(np.array([[640 + 300 * 0.57, 480], [640 + 300 * 0.58, 480]]))
    assert ok.tolist() == [True, False]


@pytest.mark.parametrize("cls, kw, field", [
    (DoubleSphere, {"alpha": 1.0}, "alpha"), (DoubleSphere, {"xi": -1.5}, "xi"), (EUCM, {"beta": 0.0}, "beta"),
    (Omni, {"xi": -0.1}, "xi"), (EUCM, {"alpha": float("nan")}, "alpha")])
def test_parameters_a_model_cannot_take_are_refused(cls, kw, field):
    with pytest.raises(ObservationError, match=field):
        cls(K0, [], W, H, **kw)


def test_distortion_lengths_and_std_intrinsics():
    with pytest.raises(ObservationError, match="dist"):
        Equidistant(K0, [0.1, 0.0], W, H)
    with pytest.raises(ObservationError, match="dist"):
        DoubleSphere(K0, [0.1], W, H)
    with pytest.raises(ObservationError, match="std_intrinsics"):
        DoubleSphere(K0, [], W, H, [1, 1, 1, 1], xi=0.1, alpha=0.5)
    ds = DoubleSphere(K0, [], W, H, [1, 1, 1, 1, 0.01, 0.02], xi=0.1, alpha=0.5)
    assert ds.intrinsic_names == ("fx", "fy", "cx", "cy", "xi", "alpha")
    assert ds.intrinsics.tolist() == [300, 310, 640, 480, 0.1, 0.5]
    om = Omni(K0, [0.1, 0.01, 0, 0], W, H, [1, 1, 1, 1, 0.02, 0.01, 0.001, 0, 0], xi=0.8)
    assert len(om.intrinsics) == 5 + 12 and om.n_core == 5


def test_the_registry_names_every_model_by_kalibrs_names():
    assert set(CAMERA_MODELS) == {("pinhole", "radtan"), ("pinhole", "equidistant"), ("omni", "radtan"),
                                  ("ds", "none"), ("eucm", "none")}
    rng = np.random.default_rng(0)
    for name, pair in MODEL_NAMES.items():
        assert camera_class(name) is camera_class(*pair) is CAMERA_MODELS[pair]
        assert random_camera(name, rng).name == name
    assert camera_class("ds") is DoubleSphere and camera_class("omni") is Omni and camera_class() is Camera
    with pytest.raises(KeyError, match="known"):
        camera_class("pinhole", "fov")
