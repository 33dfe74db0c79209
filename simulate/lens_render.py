"""Rendering a board through a lens (any ``calib_core.data.cameras`` model): every supersampled pixel's ray
(``unproject``) meets the board plane, which is sampled there (``cv2.remap`` of the board's texture), then the
image is averaged down. Pixel-centre conventions as ``simulate.camera.render_board_image``'s: supersampled pixel
``xs`` sits at image x = (xs + 0.5)/s - 0.5 and texel u at board x = (u + 0.5)/ppm, so rendered corners sit where the
model projects them. Frames: camera ``{C}``, board ``{W}`` (plane z = 0); metres, pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import BACKGROUND, CameraError, board_texture, checkerboard_corners, detect_corners
from .lens import edge_points

MAX_TEXTURE_PPM = 20000.0
"""Texels per metre of the finest texture a render uses."""


def render_board_lens(camera, T_cam_board: np.ndarray, spec, supersample: int = 4, texel_px: float = 0.5,
                      texture: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """Grey uint8 image (height, width) of the board seen through ``camera`` with pose ``T_cam_board`` on a uniform
    background; ``spec`` a BoardSpec or SimOptions (outline and, without ``texture``, the checkerboard);
    ``texture``: (image, texels per metre) of another pattern (texel (v, u) covers board xy ``[u, u+1) x [v, v+1)``
    divided by it). Only the board's bounding box in the image is traced."""
    from .camera import BoardSpec

    b = BoardSpec.of(spec)
    s = int(supersample)
    R, t = T_cam_board[:3, :3], T_cam_board[:3, 3]
    E = edge_points(b.outline(), 32) @ R.T + t
    img = np.full((camera.height * s, camera.width * s), BACKGROUND, np.float32)
    ok = camera.valid(E)
    if not ok.any():
        return np.full((camera.height, camera.width), int(BACKGROUND), np.uint8)
    uv = camera.project(E[ok])
    lo = np.clip(np.floor((uv.min(0) - 2 + 0.5) * s).astype(int), 0, [camera.width * s, camera.height * s])
    hi = np.clip(np.ceil((uv.max(0) + 2 + 0.5) * s).astype(int), 0, [camera.width * s, camera.height * s])
    if ok.all() and np.all(hi > lo):
        if texture is None:
            ppm_needed = max(camera.K[0, 0], camera.K[1, 1]) * s / np.linalg.norm(E, axis=1).min() / texel_px
            texture = board_texture(b, min(ppm_needed, MAX_TEXTURE_PPM))
        img[lo[1]:hi[1], lo[0]:hi[0]] = _traced(camera, R, t, lo, hi, s, *texture)
    else:
        raise CameraError("render_board_lens: the board is not wholly in the lens's field")
    out = cv2.resize(img, (camera.width, camera.height), interpolation=cv2.INTER_AREA) if s > 1 else img
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


RAY_STEP = 4
"""Rays are traced every ``RAY_STEP`` supersampled pixels and the board-plane coordinates interpolated between them
(bilinear; the lens's map is smooth at that scale: the rendered corners keep to the projection, tests/simulate)."""


def _traced(camera, R, t, lo, hi, s, tex, ppm) -> np.ndarray:
    """The supersampled window ``[lo, hi)`` (x, y) of the render: each pixel's ray onto the board plane (rays every
    ``RAY_STEP`` pixels, the plane coordinates interpolated between them)."""
    g = RAY_STEP
    nx, ny = (hi[0] - lo[0] - 1) // g + 2, (hi[1] - lo[1] - 1) // g + 2
    xs, ys = np.meshgrid(lo[0] + g * np.arange(nx), lo[1] + g * np.arange(ny))
    uv = np.stack([(xs + 0.5) / s - 0.5, (ys + 0.5) / s - 0.5], axis=-1)
    rays, ok = camera.unproject(uv)
    n = R[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (n @ t) / (rays @ n)                                   # along each ray to the plane
        xy = np.einsum("...a,ab->...b", depth[..., None] * rays - t, R)[..., :2]
    ok &= np.isfinite(depth) & (depth > 0)
    cx = np.where(ok, xy[..., 0] * ppm - 0.5, np.nan).astype(np.float32)
    cy = np.where(ok, xy[..., 1] * ppm - 0.5, np.nan).astype(np.float32)
    fx, fy = np.meshgrid(np.arange(hi[0] - lo[0], dtype=np.float32) / g, np.arange(hi[1] - lo[1], dtype=np.float32) / g)
    mx = cv2.remap(cx, fx, fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    my = cv2.remap(cy, fx, fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    bad = ~(np.isfinite(mx) & np.isfinite(my))
    mx[bad], my[bad] = -1e6, -1e6
    return cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=BACKGROUND)


def image_corners(camera, T_cam_board: np.ndarray, spec, rng: np.random.Generator, image_noise_std: float,
                  supersample: int) -> np.ndarray:
    """``image`` mode through a lens: render, add N(0, ``image_noise_std``) grey-level noise, detect the inner
    corners (``cv2.findChessboardCornersSB``); CameraError when they are not found."""
    img = render_board_lens(camera, T_cam_board, spec, supersample)
    if image_noise_std > 0:
        img = np.clip(np.rint(img + rng.normal(0.0, image_noise_std, img.shape)), 0, 255).astype(np.uint8)
    uv = detect_corners(img, spec)
    if uv is None or len(uv) != len(checkerboard_corners(spec)):
        raise CameraError("checkerboard not detected in the image rendered through the lens")
    return uv


def render_lens_view(camera, T_cam_board: np.ndarray, spec, supersample: int, texture=None) -> np.ndarray:
    """``render_board_lens`` of the checkerboard or of a pattern (``texture(ppm) -> (image, ppm)``,
    ``simulate.patterns.texture_source``), its texture fine enough for half a supersampled pixel at the board's
    nearest corner (at least 0.05 m away). Grey uint8 image; CameraError as ``render_board_lens``."""
    from .camera import BoardSpec

    outline = BoardSpec.of(spec).outline()
    corners = np.column_stack([outline, np.zeros(len(outline))]) @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    d = np.linalg.norm(corners, axis=1).min()
    tex = None if texture is None else texture(camera.K[0, 0] * supersample / max(d, 0.05) / 0.5)
    return render_board_lens(camera, T_cam_board, spec, supersample, texture=tex)
