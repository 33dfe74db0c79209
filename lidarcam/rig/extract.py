"""From a dataset folder to ``Observations``: board poses from images, board points from scans, per-pose diagnostics.

Per pose: the board's corners (``cv2.findChessboardCornersSB`` for a checkerboard, its order made canonical;
``cv2.aruco`` for a ChArUco board or an AprilGrid, each corner with its identity, a board cut by the image edge
counting above ``lidarcam.rig.detect.check_spread``) -> the board pose (undistorted corners ->
``cv2.solvePnP(SOLVEPNP_IPPE)`` + ``cv2.solvePnPRefineLM``, or the rays of camera.yaml's lens model) ->
reprojection RMS (pixels, through the lens). Scan: no-returns dropped, optional background subtraction, breakpoint
clustering (adaptive threshold of Borges & Aldon 2004), split-and-merge into line segments, and the segment that
agrees with the camera's view of the board is kept (hard gates: ranges within the camera-to-board distances
+- ``max_offset_m``, length at most the board's diagonal; ranking: distance to the board centre and the expected
chord). A manual bearing window from windows.yaml replaces the search. A pose whose board or segment is not
found is skipped with its reason, never used. The camera side is ``lidarcam.rig.detect``, the scan side
``lidarcam.rig.segment``, the
options and diagnostics ``lidarcam.rig.extract_options``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from calib_core.data.camera import CameraModel as Lens
from calib_core.data.observations import BoardObservation, Observations
from calib_core.errors import ObservationError
from calib_core.geometry.transforms import transform_points

from .dataset import Dataset, DatasetError, Pose, Scan
from .detect import BoardDetection
from .extract_options import CURVATURE_CHI2, AmbiguousSegment, ExtractionError, ExtractOptions, PoseDiagnostics
from .lens_detect import detect_board_lens
from .scan_noise import NoiseEstimate, estimate_noise
from .segment import describe_segment, find_board_segment

__all__ = ["CURVATURE_CHI2", "AmbiguousSegment", "ExtractOptions", "ExtractionError", "PoseDiagnostics", "extract",
           "direction_line", "extract_pose", "format_diagnostics", "noise_line"]


NOISE_ROUNDS = 4
"""Most rounds of segment search and noise estimate (``_estimate_noise``)."""


# --------------------------------------------------------------------------------------------------- per pose
def extract_pose(pose: Pose, dataset: Dataset, opts: ExtractOptions | None = None, det: BoardDetection | None = None,
                 static: np.ndarray | None = None
                 ) -> tuple[BoardObservation | None, PoseDiagnostics, BoardDetection | None]:
    """One pose: (board observation or None, diagnostics, camera detection or None). Never raises for bad data.
    ``det``: the camera detection made already; ``static``: the scan's static points (lidarcam.rig.multipose)."""
    opts = opts or ExtractOptions()
    diag = PoseDiagnostics(pose.name)
    try:
        if pose.error is not None:
            raise pose.error
        if det is None:
            det = detect_board_lens(pose.read_image(), dataset.camera, dataset.board, opts.detector_flags, pose.corners)
        diag.n_corners = len(det.corners)
        diag.reproj_rms_px = det.reproj_rms_px
        diag.cam_distance_m = float(np.linalg.norm(
            transform_points(det.T_cam_board, [[*dataset.board.centre, 0.0]])[0]))
        if det.reproj_rms_px > opts.max_reproj_px:
            raise ExtractionError(f"corner reprojection RMS {det.reproj_rms_px:.2f} px > {opts.max_reproj_px} px")
        scan = pose.scan
        diag.n_scan = len(scan)
        if pose.window is not None:
            lo, hi = pose.window
            idx = np.flatnonzero((scan.bearing >= lo) & (scan.bearing <= hi))
            diag.source = "window"
            if len(idx) < opts.min_points:
                raise ExtractionError(f"manual window {math.degrees(lo):.1f}..{math.degrees(hi):.1f} deg holds "
                                      f"{len(idx)} points (< {opts.min_points})")
        else:
            diag.source = "auto"
            idx = find_board_segment(scan, det.T_cam_board, dataset.board, opts, dataset.background, diag, static)
        _board_finish(scan, idx, diag)
        if diag.source == "window" and diag.line_rms_mm > 1000 * opts.split_tol:
            diag.notes.append(f"window points fit a line only to {diag.line_rms_mm:.0f} mm RMS")
        obs = board_observation(det.T_cam_board, dataset, scan.points[idx], det.corners, opts,
                                det.corners_board(dataset.board))
        diag.used = True
        return obs, diag, det
    except (ExtractionError, DatasetError) as err:
        diag.reason = str(err)
        diag.ambiguous = list(getattr(err, "segments", []))
        return None, diag, det


def board_observation(T_cam_board: np.ndarray, dataset: Dataset, points: np.ndarray, corners: np.ndarray | None,
                      opts: ExtractOptions, corners_board: np.ndarray | None = None) -> BoardObservation:
    """One extracted board: its camera pose, scan points and corners (``corners_board``: their board-frame
    positions; default the whole grid of ``dataset.board``), the outline as ``opts.outline_kind`` reads it (left out
    for ``none``)."""
    outline = None if opts.outline_kind == "none" else dataset.board.outline
    if corners is not None and corners_board is None:
        corners_board = dataset.board.corners
    return BoardObservation(T_cam_board, outline, points, corners, None if corners is None else corners_board,
                            outline_kind=opts.outline_kind)


def _detect_all(dataset: Dataset, opts: ExtractOptions) -> dict[str, BoardDetection | Exception]:
    """Camera side of every pose: its detection, or the error that stops it."""
    out: dict[str, BoardDetection | Exception] = {}
    for pose in dataset.poses:
        try:
            if pose.error is not None:
                raise pose.error
            out[pose.name] = detect_board_lens(pose.read_image(), dataset.camera, dataset.board, opts.detector_flags,
                                          pose.corners)
        except (ExtractionError, DatasetError) as err:
            out[pose.name] = err
    return out


def _board_finish(obs_scan: Scan, idx: np.ndarray, diag: PoseDiagnostics) -> None:
    length, rmid, rms = describe_segment(obs_scan, idx)
    diag.segment = (int(idx[0]), int(idx[-1]) + 1)
    diag.n_points = len(idx)
    diag.bearing_deg = (math.degrees(obs_scan.bearing[idx[0]]), math.degrees(obs_scan.bearing[idx[-1]]))
    diag.length_m, diag.range_m, diag.line_rms_mm = length, rmid, 1000 * rms


def _resolve_ambiguous(dataset: Dataset, boards: list, diags: list[PoseDiagnostics], dets: dict,
                       opts: ExtractOptions) -> None:
    """Second pass over ambiguous poses: calibrate on the unambiguous boards (``zhang_pless``, or ``vasconcelos``
    with fewer than 5 boards or when it fails: both fast, point-to-plane), then keep the candidate
    segment whose points lie on the board plane through that extrinsic, when it is clearly the best; otherwise
    the pose stays skipped and its reason says what the extrinsic showed."""
    todo = [k for k, d in enumerate(diags) if d.ambiguous]
    good = [replace(b, corners_px=None, corners_board=None) for b in boards if b is not None]
    if not todo or len(good) < 3:
        return
    from calib_core.entry import calibrate
    from calib_core.geometry.transforms import invert_T

    res = calibrate(Observations(tuple(good)), "zhang_pless") if len(good) >= 5 else None
    if res is None or not res.ok:
        res = calibrate(Observations(tuple(good)), "vasconcelos")
    if not res.ok:
        return
    T_cam_lidar = invert_T(res.T_lidar_cam)
    by_name = {p.name: p for p in dataset.poses}
    for k in todo:
        d, pose = diags[k], by_name[diags[k].name]
        T_cb = dets[d.name].T_cam_board
        n, off = T_cb[:3, 2], float(T_cb[:3, 2] @ T_cb[:3, 3])
        rms = []
        for i0, i1 in d.ambiguous:
            P = transform_points(T_cam_lidar, np.column_stack([pose.scan.points[i0:i1], np.zeros(i1 - i0)]))
            rms.append(float(np.sqrt(np.mean((P @ n - off) ** 2))))
        order = np.argsort(rms)
        best, second = rms[order[0]], rms[order[1]] if len(rms) > 1 else math.inf
        what = ", ".join(f"{math.degrees(pose.scan.bearing[a]):.1f}..{math.degrees(pose.scan.bearing[b - 1]):.1f} "
                         f"deg at {1000 * r:.0f} mm" for (a, b), r in zip(d.ambiguous, rms, strict=True))
        if best < opts.split_tol and best < opts.resolve_ratio * second:
            i0, i1 = d.ambiguous[order[0]]
            idx = np.arange(i0, i1)
            boards[k] = board_observation(T_cb, dataset, pose.scan.points[idx], dets[d.name].corners, opts,
                                          dets[d.name].corners_board(dataset.board))
            d.used, d.reason = True, None
            _board_finish(pose.scan, idx, d)
            d.notes.append(f"ambiguous segments resolved by the extrinsic of {len(good)} other boards "
                           f"(point-to-plane RMS: {what})")
        else:
            d.reason += f"; the extrinsic of {len(good)} other boards does not settle it ({what})"


def _merge_duplicates(boards: list, diags: list[PoseDiagnostics], groups: list[int]) -> tuple[list, dict]:
    """One board per duplicate group: the camera pose of the member with the lowest reprojection RMS and the scan
    points of all members (ordered by bearing). Returns (boards, representative pose -> merged pose names)."""
    by_group: dict[int, list[int]] = {}
    for k, d in enumerate(diags):
        if d.used:
            by_group.setdefault(groups[k], []).append(k)
    out, merged = [], {}
    for members in by_group.values():
        rep = min(members, key=lambda k: diags[k].reproj_rms_px)
        pts = np.vstack([boards[k].scan for k in members])
        pts = pts[np.argsort(np.arctan2(pts[:, 1], pts[:, 0]), kind="stable")]
        for k in members:
            diags[k].board_index = len(out)
            if k != rep:
                diags[k].notes.append(f"near-duplicate of pose {diags[rep].name}: merged into its board")
        if len(members) > 1:
            merged[diags[rep].name] = [diags[k].name for k in members if k != rep]
        out.append(replace(boards[rep], scan=pts))
    return out, merged


def extract(dataset: Dataset, opts: ExtractOptions | None = None) -> tuple[Observations, list[PoseDiagnostics]]:
    """Every pose of ``dataset`` -> (Observations of the usable poses, diagnostics of every pose).

    The camera side runs first for every pose; near-duplicate poses (lidarcam.rig.multipose.duplicate_groups) are
    grouped;
    with no background.csv the points that stay put across the groups are dropped (``opts.auto_background``);
    then each pose's board segment is searched for, and a group's boards are merged into one
    (``opts.merge_duplicates``). ``Observations.meta`` holds ``poses`` (the pose name of each board, in order),
    ``skipped`` (pose -> reason), ``merged`` (pose -> the near-duplicates merged into its board),
    ``reproj_rms_px`` per board, ``dataset`` (the folder), ``scan_direction`` and ``scan_direction_source`` (how
    the scans were read: ``lidarcam.rig.dataset.direction``) and ``extraction_noise`` (the range noise and arc
    threshold used and whether each was given or estimated from the boards' segments: ``lidarcam.rig.scan_noise``; the
    options' None values are estimated before the segment search). Every board carries its detected corners (distorted
    pixels, canonical order) and their board-frame positions, and the observations the camera intrinsics, so the
    joint model over corners and ranges applies (``meta["camera_note"]`` says why not when the intrinsics do not
    fit its ``calib_core`` camera model). The ground truth of a simulated dataset
    (ground_truth.yaml ``T_lidar_cam``) becomes ``T_lidar_cam_true``.
    """
    from .multipose import duplicate_groups, static_masks

    opts = opts or ExtractOptions()
    dets = _detect_all(dataset, opts)
    Ts = [d.T_cam_board if isinstance(d, BoardDetection) else None for d in dets.values()]
    groups = duplicate_groups(Ts, opts.duplicate_deg, opts.duplicate_m) if opts.merge_duplicates \
        else list(range(len(Ts)))
    statics = [None] * len(Ts)
    if opts.auto_background and dataset.background is None:
        statics = static_masks([p.scan if p.error is None else None for p in dataset.poses], groups,
                               opts.static_tol_m)
    boards, diags = [], []
    camera, camera_note = _camera(dataset)
    noise = _estimate_noise(dataset, dets, statics, opts)
    opts = replace(opts, range_sigma_m=noise.range_sigma_m, max_curvature_chi2=noise.max_curvature_chi2)
    for k, pose in enumerate(dataset.poses):
        det = dets[pose.name]
        if isinstance(det, Exception):
            obs, diag = None, PoseDiagnostics(pose.name, reason=str(det))
        else:
            obs, diag, _ = extract_pose(pose, dataset, opts, det, statics[k])
        boards.append(obs)
        diags.append(diag)
    _resolve_ambiguous(dataset, boards, diags, dets, opts)
    boards, merged = _merge_duplicates(boards, diags, groups)
    gt = dataset.ground_truth.get("T_lidar_cam") if dataset.ground_truth else None
    if isinstance(gt, dict):
        gt = gt.get("matrix")
    reps = {}
    for d in diags:
        if d.used and d.board_index not in reps and not any(n.startswith("near-duplicate") for n in d.notes):
            reps[d.board_index] = d
    meta = {"source": "lidarcam extract", "dataset": str(dataset.root),
            "poses": [reps[i].name for i in range(len(boards))],
            "skipped": {d.name: d.reason for d in diags if not d.used},
            "merged": merged,
            "reproj_rms_px": [reps[i].reproj_rms_px for i in range(len(boards))],
            "extraction_noise": noise.to_dict(),
            "scan_direction": dataset.scan_direction, "scan_direction_source": dataset.scan_direction_source}
    if dataset.camera.note:
        meta["camera_file_note"] = dataset.camera.note
    if camera is None:
        boards = [replace(b, corners_px=None, corners_board=None) for b in boards]
        meta["camera_note"] = camera_note
    return Observations(tuple(boards), None if gt is None else np.asarray(gt, float), meta, camera), diags


def _estimate_noise(dataset: Dataset, dets: dict, statics: list, opts: ExtractOptions) -> NoiseEstimate:
    """The range noise and arc threshold (``lidarcam.rig.scan_noise``) from each pose's board segment, found with no arc
    test; options given are kept. The segments depend on the noise (breakpoints, split tolerance), so the search and the
    estimate are repeated from the default until the noise changes by less than 5% (at most ``NOISE_ROUNDS``)."""
    if opts.range_sigma_m is not None and opts.max_curvature_chi2 is not None:
        return estimate_noise([], opts.range_sigma_m, opts.max_curvature_chi2)
    sigma, est = opts.sigma_m, None
    for _ in range(NOISE_ROUNDS):
        survey = replace(opts, range_sigma_m=sigma, max_curvature_chi2=math.inf, skip_ambiguous=False)
        est = estimate_noise(_board_segments(dataset, dets, statics, survey), opts.range_sigma_m,
                             opts.max_curvature_chi2)
        if est.range_source != "estimated" or abs(est.range_sigma_m - sigma) < 0.05 * sigma:
            break
        sigma = est.range_sigma_m
    return est


def _board_segments(dataset: Dataset, dets: dict, statics: list, opts: ExtractOptions) -> list[np.ndarray]:
    """Each detected pose's board segment (K,2 lidar points) as the segment search finds it with ``opts``."""
    segments = []
    for k, pose in enumerate(dataset.poses):
        det = dets[pose.name]
        if isinstance(det, Exception) or pose.error is not None or pose.window is not None:
            continue
        try:
            idx = find_board_segment(pose.scan, det.T_cam_board, dataset.board, opts, dataset.background, None,
                                     statics[k])
        except ExtractionError:
            continue
        segments.append(pose.scan.points[idx])
    return segments


def _camera(dataset: Dataset) -> tuple[Lens | None, str]:
    """The dataset's intrinsics for the observations (the boards then carry their detected corners), or None and
    why the joint model cannot use them."""
    try:
        return dataset.camera.core(), ""
    except ObservationError as err:
        return None, f"image corners left out, the joint model cannot use the camera: {err}"


def direction_line(meta: dict) -> str:
    """How the scans were read: ``scans read clockwise (lidar.yaml): bearings mirrored``."""
    d, src = meta.get("scan_direction", "ccw"), meta.get("scan_direction_source", "default")
    if src == "default":
        return "scans read counter-clockwise (no scan direction declared: --scan-direction or lidar.yaml)"
    return f"scans read {'clockwise' if d == 'cw' else 'counter-clockwise'} ({src})" + \
        (": bearings mirrored" if d == "cw" else "")


def noise_line(meta: dict) -> str:
    """The extraction's range noise and arc test with their sources, from ``Observations.meta``."""
    n = meta.get("extraction_noise")
    if not n:
        return "range noise: not recorded"
    return NoiseEstimate(n["range_sigma_m"], n["range_source"], n["max_curvature_chi2"], n["curvature_source"],
                         n.get("n_segments", 0),
                         tuple(math.nan if q is None else q for q in n.get("curvature_quartiles", [None, None])),
                         n.get("why", "")).describe()


def format_diagnostics(diags: list[PoseDiagnostics]) -> str:
    """A fixed-width table of the diagnostics, one pose a line, then the skip reasons."""
    head = f"{'pose':>8} {'board':>5} {'corners':>7} {'reproj_px':>9} {'dist_m':>7} {'src':>6} {'points':>6} " \
           f"{'bearing_deg':>15} {'len_m':>6} {'line_mm':>7}"
    lines = [head]
    for d in diags:
        b = "-" if d.board_index is None else str(d.board_index)
        br = "-" if d.bearing_deg is None else f"{d.bearing_deg[0]:.1f}..{d.bearing_deg[1]:.1f}"

        def f(v, fmt):
            return "-" if not math.isfinite(v) else format(v, fmt)

        lines.append(f"{d.name:>8} {b:>5} {d.n_corners or '-':>7} {f(d.reproj_rms_px, '.3f'):>9} "
                     f"{f(d.cam_distance_m, '.2f'):>7} "
                     f"{d.source or '-':>6} {d.n_points:>6} {br:>15} {f(d.length_m, '.3f'):>6} "
                     f"{f(d.line_rms_mm, '.1f'):>7}" + ("" if d.used else "  SKIPPED"))
    skipped = [d for d in diags if not d.used]
    for d in skipped:
        lines.append(f"skipped {d.name}: {d.reason}")
    for d in diags:
        for n in d.notes:
            lines.append(f"note {d.name}: {n}")
    lines.append(f"{sum(d.used for d in diags)} of {len(diags)} poses used")
    return "\n".join(lines)

