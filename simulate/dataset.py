"""A simulated real-rig dataset folder (docs/dataset.md layout) with its ground truth, for tests and demos.

``write_dataset(options, seed, out_dir)`` draws a scene as ``generate`` does (``sample_scene``; each board must
also be detected in its rendered image), renders one image per pose (``render_board_image``, then Gaussian blur,
grey-level noise and optional lens distortion), casts one full scan per pose in a room of four walls with some
clutter, and writes camera.yaml, board.yaml, ``NNN.png`` + ``NNN.csv`` (or one ``scans.csv``), background.csv
(the room without the board) and ground_truth.yaml. Units: metres, radians, pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from calib_core.geometry.transforms import invert_T, make_T

from . import trial_rngs
from .camera import BACKGROUND, BoardSpec, camera_matrix, checkerboard_corners, render_board_image, undistort_points
from .lens import is_default, true_camera
from .lens_render import render_lens_view
from .lidar import beam_bearings, board_ranges, scan_chords
from .options import SimOptions
from .patterns import Pattern, texture_source
from .rig import refuse_rig_conditions
from .scene import Scene, sample_scene


@dataclass(frozen=True)
class RoomOptions:
    """The static surroundings of the lidar, drawn per dataset.

    Attributes:
        wall_min_m, wall_max_m: distance of each of the 4 walls from the lidar (uniform), metres.
        cabinet_len_m, cabinet_range_m: a flat cabinet front (longer than a board) at this range, metres.
        cabinet_bearing_deg: bearing of the cabinet's centre (degrees).
        pillar_radius_m, pillar_range_m, pillar_bearing_deg: a round pillar (too small to pass for a board).
    """

    wall_min_m: float = 8.0
    wall_max_m: float = 12.0
    cabinet_len_m: float = 2.0
    cabinet_range_m: float = 4.5
    cabinet_bearing_deg: float = 70.0
    pillar_radius_m: float = 0.1
    pillar_range_m: float = 4.0
    pillar_bearing_deg: float = -65.0


def room_ranges(bearings: np.ndarray, walls: np.ndarray, yaw: float, room: RoomOptions) -> np.ndarray:
    """Range (K,) along each beam to the room: 4 walls (distances ``walls`` (4,) front, left, back, right, the
    room turned by ``yaw``), the cabinet and the pillar; nearest hit wins."""
    u = np.column_stack([np.cos(bearings), np.sin(bearings)])
    r = np.full(len(bearings), np.inf)
    for k, dist in enumerate(walls):
        a = yaw + k * np.pi / 2
        n = np.array([np.cos(a), np.sin(a)])
        den = u @ n
        with np.errstate(divide="ignore"):
            rk = np.where(den > 1e-9, dist / den, np.inf)
        r = np.minimum(r, rk)
    # cabinet: a segment facing the lidar
    b = np.radians(room.cabinet_bearing_deg)
    c = room.cabinet_range_m * np.array([np.cos(b), np.sin(b)])
    t = np.array([-np.sin(b), np.cos(b)])
    n = c / np.linalg.norm(c)
    den = u @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        rc = np.where(den > 1e-9, (c @ n) / den, np.inf)
        s = rc[:, None] * u @ t - c @ t
    r = np.minimum(r, np.where(np.abs(s) <= room.cabinet_len_m / 2, rc, np.inf))
    # pillar: a circle
    b = np.radians(room.pillar_bearing_deg)
    p = room.pillar_range_m * np.array([np.cos(b), np.sin(b)])
    proj = u @ p
    disc = proj ** 2 - (p @ p - room.pillar_radius_m ** 2)
    rp = np.where(disc >= 0, proj - np.sqrt(np.maximum(disc, 0)), np.inf)
    return np.minimum(r, np.where(rp > 0, rp, np.inf))


def distortion_maps(K: np.ndarray, dist: np.ndarray, width: int, height: int):
    """Where each pixel of a distorted (width x height) image lies in a pinhole canvas: (K_big, W_big, H_big,
    map_x, map_y). Render the pinhole view with ``K_big`` on ``W_big x H_big``, then ``cv2.remap`` it with the
    maps (see ``distort_image``)."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    und = undistort_points(np.column_stack([u.ravel(), v.ravel()]), K, dist)
    lo = np.floor(und.min(axis=0)) - 2
    hi = np.ceil(und.max(axis=0)) + 2
    Kb = np.asarray(K, float).copy()
    Kb[0, 2] -= lo[0]
    Kb[1, 2] -= lo[1]
    mx = (und[:, 0] - lo[0]).reshape(height, width).astype(np.float32)
    my = (und[:, 1] - lo[1]).reshape(height, width).astype(np.float32)
    return Kb, int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1, mx, my


def distort_image(big: np.ndarray, maps) -> np.ndarray:
    """The distorted image (float32) sampled from the pinhole canvas ``big`` rendered as ``distortion_maps`` says."""
    _, _, _, mx, my = maps
    return cv2.remap(big.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=BACKGROUND)


def _opencv_camera_yaml(path: Path, width: int, height: int, K: np.ndarray, dist: np.ndarray) -> None:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", int(width))
    fs.write("image_height", int(height))
    fs.write("camera_matrix", np.asarray(K, np.float64))
    fs.write("distortion_coefficients", np.asarray(dist, np.float64).reshape(1, -1))
    fs.release()


def _plain_camera_yaml(path: Path, width: int, height: int, K: np.ndarray, dist: np.ndarray) -> None:
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in K)
    path.write_text(f"# pinhole intrinsics, OpenCV distortion model (k1, k2, p1, p2, k3)\nimage_width: {width}\n"
                    f"image_height: {height}\ncamera_matrix: [{rows}]\n"
                    f"distortion_coefficients: [{', '.join(repr(float(v)) for v in dist)}]\n")


def _mat_yaml(M: np.ndarray, indent: str = "    ") -> str:
    return "\n".join(f"{indent}- [{', '.join(repr(float(v)) for v in row)}]" for row in np.asarray(M))


def write_board_yaml(path, options: SimOptions, outline_sim: np.ndarray) -> None:
    """board.yaml (docs/dataset.md) of the simulated board; ``outline_sim`` (V,2) in the simulator's board frame,
    shifted here to the dataset's frame (origin at the first inner corner)."""
    spec = BoardSpec.of(options)
    c0 = checkerboard_corners(spec)[0]
    Path(path).write_text(
        "# checkerboard: inner corners cols x rows, square side and the board's outline, metres.\n"
        "# board frame: origin at the first inner corner, x along a row, y along a column, plane z = 0.\n"
        f"cols: {spec.squares_x - 1}\nrows: {spec.squares_y - 1}\nsquare_m: {spec.square_m!r}\n"
        "outline_m:\n" + _mat_yaml(np.asarray(outline_sim) - c0[:2], "  ") + "\n"
        "# colour of the square between the first inner corners (x, y in [0, square_m])\norigin_square: light\n")


def write_dataset(options: SimOptions, seed: int, out_dir, *, trial: int = 0, room: RoomOptions | None = None,
                  distortion=(0.0, 0.0, 0.0, 0.0, 0.0), blur_sigma_px: float = 0.7, image_noise_std: float = 2.0,
                  scan_columns: str = "bearing_range", keyed_scans: bool = False, camera_style: str = "opencv",
                  dropout_prob: float = 0.002, image_format: str = "png", pattern: Pattern | None = None,
                  cut_every: int = 0) -> Path:
    """Write a simulated dataset folder and return its path.

    ``options``: the scene, lidar and camera (``cam_width``, ``cam_height``, ``focal_px``, board, noise_mm;
    ``pose_mode`` is ignored: the images are what the camera sees). ``distortion``: OpenCV coefficients
    (k1, k2, p1, p2, k3) applied to the images and written to camera.yaml. ``scan_columns``: ``bearing_range``
    or ``xy``. ``keyed_scans``: one scans.csv instead of NNN.csv. ``camera_style``: ``opencv`` (%YAML:1.0 via
    cv2.FileStorage) or ``plain``. ``dropout_prob``: share of beams with no return (written as range 0).
    The ground truth (T_lidar_cam, T_cam_board per pose in the dataset's board frame) is in ground_truth.yaml.

    ``pattern``: a ChArUco board or an AprilGrid (``simulate.patterns``) instead of the checkerboard, centred on the
    board (board.yaml in its form, the dataset's board frame the pattern's). A lens other than the plain pinhole
    (``cam_model``, ``cam_params``: ``simulate.lens``) renders through the model (``render_board_lens``) and is
    written into camera.yaml (``camera_model``, ``distortion_model``, the model's parameters). ``cut_every``: every
    ``cut_every``-th pose (0: none) has its board slid along its scan chord until 20-45% of its corners leave the
    image (a board cut by the image edge; the scan still crosses it), where such a slide exists.
    """
    o = options
    refuse_rig_conditions(o, "write_dataset")
    room = room or RoomOptions()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng_geo, rng_lidar, rng_cam = trial_rngs(o, seed, trial)
    rng_room = np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=(7919, int(trial))))
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    dist = np.asarray(distortion, float).ravel()
    lens = None if is_default(o) else true_camera(o, K)
    if lens is not None and np.any(dist != 0):
        raise ValueError("write_dataset: distortion is the pinhole's; a lens (cam_model) carries its own")
    spec = BoardSpec.of(o)
    cols, rows = spec.squares_x - 1, spec.squares_y - 1
    c0 = checkerboard_corners(spec)[0] if pattern is None else np.r_[pattern.offset(spec.size_m), 0.0]
    T_sim_ds = make_T(np.eye(3), c0)  # dataset board frame (origin at the first inner corner) -> sim board frame
    P_ds = None if pattern is None else pattern.corners()

    images: list[np.ndarray] = []
    render = _renderer(o, K, dist, lens, pattern, blur_sigma_px, image_noise_std, rng_cam)

    def accept(T_lidar_cam, T_lidar_board) -> bool:
        img = render(invert_T(T_lidar_cam) @ T_lidar_board)
        if pattern is None and lens is None:
            found, _ = cv2.findChessboardCornersSB(img, (cols, rows), flags=cv2.CALIB_CB_ACCURACY)
            if not found:
                return False
        images.append(img)
        return True

    scene = sample_scene(o, rng_geo, accept=accept)
    if cut_every > 0:
        scene = _cut_boards(o, scene, lens or _PinholeView(K, o.cam_width, o.cam_height), T_sim_ds,
                            checkerboard_corners(spec) if P_ds is None else P_ds @ T_sim_ds[:3, :3].T + T_sim_ds[:3, 3],
                            cut_every, images, render)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    walls = rng_room.uniform(room.wall_min_m, room.wall_max_m, 4)
    yaw = float(rng_room.uniform(-np.pi / 4, np.pi / 4))
    r_room = room_ranges(bearings, walls, yaw, room)
    sigma = o.noise_mm / 1000.0

    def noisy(r: np.ndarray) -> np.ndarray:
        r = r + rng_lidar.normal(0.0, sigma, len(r))
        r[~np.isfinite(r) | (r > o.lidar_max_range_m) | (rng_lidar.random(len(r)) < dropout_prob)] = 0.0
        return r

    names = [f"{i:03d}" for i in range(len(scene.T_lidar_board))]
    owners = _write_scans(out, names, scene, images, bearings, r_room, noisy, scan_columns=scan_columns,
                          keyed_scans=keyed_scans, image_format=image_format)
    if lens is not None:
        _lens_camera_yaml(out / "camera.yaml", lens)
    else:
        _write_camera_yaml(out / "camera.yaml", camera_style, o, K, dist)
    _write_board(out / "board.yaml", o, scene, pattern, c0)
    _write_ground_truth(out / "ground_truth.yaml", o, scene, T_sim_ds, names, owners, seed=seed, trial=trial,
                        sigma=sigma, walls=walls, yaw=yaw)
    return out


def _renderer(o: SimOptions, K: np.ndarray, dist: np.ndarray, lens, pattern: Pattern | None, blur_sigma_px: float,
              image_noise_std: float, rng_cam: np.random.Generator):
    """``render(T_cam_board) -> uint8 image`` of ``write_dataset``: the checkerboard or ``pattern`` through the pinhole
    (with OpenCV ``dist``) or through ``lens``, blurred, with grey-level noise."""
    spec = BoardSpec.of(o)
    maps = distortion_maps(K, dist, o.cam_width, o.cam_height) if np.any(dist != 0) else None

    texture = None if pattern is None else texture_source(pattern, spec.size_m)

    def render(T_cam_board: np.ndarray) -> np.ndarray:
        def ideal(Kr, W, H):
            if lens is not None:
                img = render_lens_view(lens, T_cam_board, spec, o.render_supersample, texture)
            else:
                img = render_board_image(Kr, T_cam_board, spec, W, H, o.render_supersample,
                                         texture=None if pattern is None else texture)
            img = img.astype(np.float32)
            if blur_sigma_px > 0:
                img = cv2.GaussianBlur(img, (0, 0), blur_sigma_px)
            return img

        img = distort_image(ideal(*maps[:3]), maps) if maps is not None else ideal(K, o.cam_width, o.cam_height)
        img = img + rng_cam.normal(0.0, image_noise_std, img.shape) if image_noise_std > 0 else img
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    return render


def _write_board(path: Path, o: SimOptions, scene: Scene, pattern: Pattern | None, c0: np.ndarray) -> None:
    """board.yaml: the checkerboard's, or ``pattern``'s form with the board's outline in its frame (origin at
    ``c0`` of the simulator's board frame)."""
    if pattern is None:
        write_board_yaml(path, o, scene.outline)
    else:
        path.write_text(pattern.board_yaml(np.asarray(scene.outline) - c0[:2]))


def _write_scans(out: Path, names, scene, images, bearings: np.ndarray, r_room: np.ndarray, noisy, *,
                 scan_columns: str, keyed_scans: bool, image_format: str) -> list[np.ndarray]:
    """Each pose's image and scan (board in front of the room, ``noisy`` ranges), and background.csv; returns
    per pose which beams the board owns."""

    def scan_rows(r: np.ndarray) -> list[tuple[float, float]]:
        if scan_columns == "xy":
            return [(float(ri * np.cos(b)), float(ri * np.sin(b))) for b, ri in zip(bearings, r, strict=True)]
        return [(float(b), float(ri)) for b, ri in zip(bearings, r, strict=True)]

    header = "x,y" if scan_columns == "xy" else "bearing_rad,range_m"
    if scan_columns not in ("xy", "bearing_range"):
        raise ValueError(f"scan_columns must be bearing_range or xy, got {scan_columns!r}")
    keyed_lines = ["pose," + header]
    owners = []
    for name, T_lb, img in zip(names, scene.T_lidar_board, images, strict=True):
        rb = board_ranges(bearings, T_lb[None], scene.outline)[0]
        owner = rb < r_room
        owners.append(owner)
        r = noisy(np.where(owner, rb, r_room))
        cv2.imwrite(str(out / f"{name}.{image_format}"), img)
        lines = [f"{a!r},{b!r}" for a, b in scan_rows(r)]
        if keyed_scans:
            keyed_lines += [f"{name},{ln}" for ln in lines]
        else:
            (out / f"{name}.csv").write_text("\n".join([header] + lines) + "\n")
    if keyed_scans:
        (out / "scans.csv").write_text("\n".join(keyed_lines) + "\n")
    bg = noisy(r_room.copy())
    (out / "background.csv").write_text("\n".join([header] + [f"{a!r},{b!r}" for a, b in scan_rows(bg)]) + "\n")
    return owners


def _write_camera_yaml(path: Path, camera_style: str, o: SimOptions, K: np.ndarray, dist: np.ndarray) -> None:
    if camera_style == "opencv":
        _opencv_camera_yaml(path, o.cam_width, o.cam_height, K, dist)
    elif camera_style == "plain":
        _plain_camera_yaml(path, o.cam_width, o.cam_height, K, dist)
    else:
        raise ValueError(f"camera_style must be opencv or plain, got {camera_style!r}")


def _write_ground_truth(path: Path, o: SimOptions, scene, T_sim_ds: np.ndarray, names, owners, *, seed: int,
                        trial: int, sigma: float, walls: np.ndarray, yaw: float) -> None:
    """ground_truth.yaml: T_lidar_cam, the range noise (metres), the room, and per pose T_cam_board (dataset board
    frame), the scan chord and the board's beam interval."""
    T_lc = scene.T_lidar_cam
    T_cb = scene.T_cam_board @ T_sim_ds
    chords = scan_chords(scene.T_lidar_board, scene.outline)
    gt = ["# ground truth of the simulated rig (lidarcam simulate.dataset). T_a_b maps frame b into frame a.",
          f"generator: lidarcam.simulate.dataset/1\nseed: {int(seed)}\ntrial: {int(trial)}",
          "T_lidar_cam:", _mat_yaml(T_lc, "  "), "T_cam_lidar:", _mat_yaml(invert_T(T_lc), "  "),
          f"range_noise_m: {sigma!r}", f"room_walls_m: [{', '.join(repr(float(w)) for w in walls)}]",
          f"room_yaw_rad: {yaw!r}", "poses:"]
    for name, T, ch, ow in zip(names, T_cb, chords, owners, strict=True):
        idx = np.flatnonzero(ow)
        gt += [f"  '{name}':", "    T_cam_board:", _mat_yaml(T, "      "),
               "    chord_m: [" + ", ".join("[" + ", ".join(repr(float(v)) for v in e) + "]" for e in ch) + "]",
               f"    board_beams: [{int(idx.min()) if len(idx) else -1}, {int(idx.max()) + 1 if len(idx) else -1}]"]
    gt.append("options:")
    gt += [f"  {k}: {str(v).lower() if isinstance(v, bool) else repr(v)}" if not isinstance(v, str) else f"  {k}: '{v}'"
           for k, v in o.to_dict().items()]
    path.write_text("\n".join(gt) + "\n")


class _PinholeView:
    """The distortion-free pinhole as ``_cut_boards`` asks a camera: ``valid`` and ``project``."""

    def __init__(self, K: np.ndarray, width: int, height: int) -> None:
        self.K, self.width, self.height = K, width, height

    def valid(self, P: np.ndarray) -> np.ndarray:
        return P[..., 2] > 1e-6

    def project(self, P: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            uvw = P @ self.K.T
            return uvw[..., :2] / uvw[..., 2:3]


CUT_SHARE = (0.2, 0.45)
"""Share of a cut board's corners (``write_dataset``'s ``cut_every``) that leave the image."""


def _cut_boards(o: SimOptions, scene: Scene, camera, T_sim_ds: np.ndarray, P_sim: np.ndarray, every: int,
                images: list, render) -> Scene:
    """``scene`` with every ``every``-th board slid along its scan chord (lidar frame) until a share ``CUT_SHARE`` of
    its corners ``P_sim`` (simulator board frame) leaves the image, keeping ``o.min_points_per_board`` lidar points on
    it; its image re-rendered into ``images``. Boards with no such slide stay whole."""
    T_lc = scene.T_lidar_cam
    T_cl = invert_T(T_lc)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    boards = np.array(scene.T_lidar_board, float)
    steps = np.linspace(0.02, 2.5, 125)[:, None] * np.array([1.0, -1.0])   # smallest slide first, either way
    for k in range(0, len(boards), every):
        ch = scan_chords(boards[k], scene.outline)[0]
        if np.isnan(ch).any():
            continue
        d = np.r_[(ch[1] - ch[0]) / np.linalg.norm(ch[1] - ch[0]), 0.0]
        for s in steps.ravel():
            T = boards[k].copy()
            T[:3, 3] += s * d
            X = P_sim @ (T_cl @ T)[:3, :3].T + (T_cl @ T)[:3, 3]
            E = np.column_stack([scene.outline, np.zeros(len(scene.outline))])
            Xe = E @ (T_cl @ T)[:3, :3].T + (T_cl @ T)[:3, 3]
            if not (camera.valid(X).all() and camera.valid(Xe).all()):
                continue
            uv = camera.project(X)
            out = ~((uv[:, 0] >= 0) & (uv[:, 0] <= camera.width - 1) & (uv[:, 1] >= 0)
                    & (uv[:, 1] <= camera.height - 1))
            if not CUT_SHARE[0] <= out.mean() <= CUT_SHARE[1]:
                continue
            if np.isfinite(board_ranges(bearings, T[None], scene.outline)[0]).sum() < o.min_points_per_board:
                continue
            boards[k] = T
            images[k] = render(T_cl @ T)
            break
    return Scene(T_lc, boards, scene.outline, scene.margins_m)


def _lens_camera_yaml(path: Path, lens) -> None:
    """camera.yaml of a ``calib_core.data.cameras`` model: the OpenCV keys, ``camera_model``, ``distortion_model``
    and the model's parameters."""
    K = np.asarray(lens.K, float)
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in K)
    n = {"pinhole-equidistant": 4}.get(lens.name, len(np.asarray(lens.dist)))
    dist = np.asarray(lens.dist, float).ravel()[:n]
    params = "".join(f"{name}: {float(getattr(lens, name))!r}\n" for name in lens.param_names)
    path.write_text(f"# {lens.name} camera (calib_core.data.cameras; Kalibr's model names)\n"
                    f"image_width: {lens.width}\nimage_height: {lens.height}\ncamera_model: {lens.camera_model}\n"
                    f"distortion_model: {lens.distortion_model}\n{params}camera_matrix: [{rows}]\n"
                    f"distortion_coefficients: [{', '.join(repr(float(v)) for v in dist)}]\n")
