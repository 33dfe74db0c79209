"""From a recording to a dataset folder: stream the bag, pick still frames, pair each with a scan, write the
docs/dataset.md layout (camera.yaml, board.yaml, NNN.png, NNN.csv ``bearing_rad,range_m``) and ``picking.json``
(why each frame was kept or skipped, the time sync). ``lidarcam extract`` and ``calibrate`` then run unchanged.

Two passes over the image topic: the first keeps only a thumbnail per frame (the quiet test, the offset
estimate), the second decodes the few candidate frames of one still run at a time again at full resolution
(read by bag time). Scans are held as one float32 row per scan, a kept candidate as PNG bytes. Memory grows
with the number of frames and scans (a thumbnail of about 20 kB and a scan row each), never with the bag's
bytes.
"""

from __future__ import annotations

import json
import math
import shutil
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from calib_core.data.observations import BoardObservation

from . import stills, timesync
from .bag import BagError, BagSource, iter_images, iter_scans, read_camera_info
from .dataset import BoardSpec, CameraModel, load_board, load_camera, make_scan
from .extract_options import ExtractionError, ExtractOptions
from .lens_detect import detect_board_lens
from .segment import find_board_segment


@dataclass
class Streams:
    """Pass one: image stamps, bag times and thumbnails (sorted by stamp); scan stamps, bearings, ranges."""

    image_ns: np.ndarray
    image_bag_ns: np.ndarray
    thumbs: np.ndarray
    image_size: tuple[int, int]
    scan_ns: np.ndarray
    bearing: np.ndarray
    ranges: np.ndarray


@dataclass
class BagConversion:
    """What ``bag_to_dataset`` did: the folder, the stream sizes, the sync, one log entry per frame and the
    kept poses (dicts as in picking.json)."""

    out: Path
    n_images: int
    n_scans: int
    scan_period_s: float
    sync: dict
    poses: list[dict] = field(default_factory=list)
    frames: list[dict] = field(default_factory=list)
    normal_spread_deg: float = math.nan

    def summary(self) -> str:
        """Counts of the reasons, one line each, then the sync."""
        counts = Counter(f["reason"].split(":", 1)[0] for f in self.frames)
        lines = [f"{self.n_images} images, {self.n_scans} scans (period {1000 * self.scan_period_s:.1f} ms)"]
        lines += [f"  {n:6d}  {k}" for k, n in counts.most_common()]
        s = self.sync
        lines.append(f"time offset {1000 * s['offset_s']:.1f} ms ({s['offset_source']}), pairing tolerance "
                     f"{1000 * s['tol_s']:.1f} ms")
        lines.append(f"{len(self.poses)} poses kept, board-normal spread {self.normal_spread_deg:.1f} deg")
        return "\n".join(lines)


def _thumbnail(gray: np.ndarray, width: int) -> np.ndarray:
    import cv2

    h, w = gray.shape
    f = max(1, int(math.ceil(w / max(width, 1))))
    return cv2.resize(gray, (w // f, h // f), interpolation=cv2.INTER_AREA)


def read_streams(src: BagSource, image_topic: str, scan_topic: str, thumb_width: int) -> Streams:
    """Pass one over the bag (module docstring); BagError when a topic holds no message or the beam layout of the
    scans changes."""
    ns, bag_ns, thumbs, size = [], [], [], None
    for fr in iter_images(src, image_topic):
        size = size or fr.gray.shape[::-1]
        if fr.gray.shape[::-1] != size:
            raise BagError(f"image topic {image_topic!r}: image size changes from {size[0]}x{size[1]} to "
                           f"{fr.gray.shape[1]}x{fr.gray.shape[0]}", file=src.path)
        ns.append(fr.stamp_ns)
        bag_ns.append(fr.bag_ns)
        thumbs.append(_thumbnail(fr.gray, thumb_width))
    if not ns:
        raise BagError(f"image topic {image_topic!r} has no message", file=src.path)
    s_ns, rows, bearing = [], [], None
    for sc in iter_scans(src, scan_topic):
        if bearing is None:
            bearing = sc.bearing
        elif len(sc.bearing) != len(bearing) or not np.allclose(sc.bearing, bearing, atol=1e-6):
            raise BagError(f"scan topic {scan_topic!r}: the beam layout (angle_min, angle_increment, count) "
                           "changes within the recording", file=src.path)
        s_ns.append(sc.stamp_ns)
        rows.append(sc.range.astype(np.float32))
    if not s_ns:
        raise BagError(f"scan topic {scan_topic!r} has no message", file=src.path)
    oi, os_ = np.argsort(ns, kind="stable"), np.argsort(s_ns, kind="stable")
    return Streams(np.asarray(ns, np.int64)[oi], np.asarray(bag_ns, np.int64)[oi], np.stack(thumbs)[oi], size,
                   np.asarray(s_ns, np.int64)[os_], bearing, np.stack(rows)[os_])


def _sync(st: Streams, motion: np.ndarray, opts: stills.PickOptions) -> tuple[timesync.Pairing, dict]:
    sync = {"offset_s": opts.time_offset_s, "offset_source": "given"}
    if opts.estimate_offset:
        est = timesync.estimate_offset(st.image_ns, motion, st.scan_ns, timesync.scan_motion(st.ranges),
                                       opts.max_offset_s)
        sync["estimate"] = asdict(est)
        if est.reliable:
            sync.update(offset_s=est.offset_s, offset_source="estimated")
        else:
            sync["offset_source"] = (f"given; the estimate {1000 * est.offset_s:.1f} ms is unreliable: peak "
                                     f"correlation {est.correlation:.2f}, halves {1000 * est.halves_s[0]:.1f} and "
                                     f"{1000 * est.halves_s[1]:.1f} ms")
    pairing = timesync.pair_nearest(st.image_ns, st.scan_ns, opts.sync_tol_s, sync["offset_s"])
    sync["tol_s"] = pairing.tol_s
    return pairing, sync


def _fetch(src: BagSource, topic: str, st: Streams, frames: list[int]) -> dict[int, np.ndarray]:
    """Pass two: the full-resolution images of the given frames (indices into ``st``), read again by bag time
    and matched by header stamp (two messages may share a bag time)."""
    out = {}
    for i in sorted(set(frames)):
        t = int(st.image_bag_ns[i])
        for fr in iter_images(src, topic, start=t, stop=t + 1):
            if fr.stamp_ns == st.image_ns[i]:
                out[i] = fr.gray
                break
        else:
            raise BagError(f"image topic {topic!r}: the frame stamped {st.image_ns[i]} ns is gone on the second "
                           "read", file=src.path)
    return out


def _segment(st: Streams, k: int, T_cam_board: np.ndarray, board: BoardSpec, eo: ExtractOptions):
    scan = make_scan(bearing=st.bearing, rng=st.ranges[k].astype(float))
    idx = find_board_segment(scan, T_cam_board, board, eo)
    return scan, idx


@dataclass
class _Ctx:
    src: BagSource
    image_topic: str
    st: Streams
    camera: CameraModel
    board: BoardSpec
    opts: stills.PickOptions
    eo: ExtractOptions
    pairing: timesync.Pairing


def _scan_still(ctx: _Ctx, run: tuple[int, int], c: int, k: int, bearing: np.ndarray, rng: np.ndarray,
                T_cam_board: np.ndarray) -> float:
    """Largest median range change (metres) of the board segment (``bearing``, ``rng`` of scan ``k``) against the
    scans paired with the frames a quarter of the run before and after frame ``c``; raises ExtractionError
    (``scan moving``) beyond ``scan_still_m`` (or its automatic value) or ``scan_still_beams``."""
    st, o = ctx.st, ctx.opts
    a, b = run
    h = max(1, min(c - a, b - 1 - c, (b - a) // 4))
    step = float(st.bearing[1] - st.bearing[0]) if len(st.bearing) > 1 else 1.0
    near = timesync.pair_nearest(st.image_ns[[c - h, c + h]], st.scan_ns, math.inf, ctx.pairing.offset_s).scan
    worst = (0.0, 0.0, 0.0)  # (median shift, end shift in beams, tolerance)
    for j in near:
        if j == k:
            continue
        try:
            s2, i2 = _segment(st, int(j), T_cam_board, ctx.board, ctx.eo)
        except ExtractionError:
            raise ExtractionError(f"scan moving: no board segment in the scan {abs(j - k)} scans away") from None
        dm, db, n = stills.scan_segment_shift(step, (bearing, rng), (s2.bearing[i2], s2.range[i2]))
        tol = o.scan_still_m if o.scan_still_m > 0 else stills.median_shift_tolerance(ctx.eo.sigma_m, n)
        dm = dm if math.isfinite(dm) else math.inf
        if dm > tol or db > o.scan_still_beams:
            raise ExtractionError(f"scan moving: board segment shifted {1000 * dm:.1f} mm (> {1000 * tol:.1f} mm) "
                                  f"/ {db:.0f} beams (> {o.scan_still_beams}) {abs(j - k)} scans away")
        worst = max(worst, (dm, db, tol))
    return worst[0]


def check_candidate(ctx: _Ctx, run: tuple[int, int], c: int, frames: dict[int, np.ndarray]):
    """Frame ``c`` of a still run: (BoardObservation, pose record) or raises ExtractionError with the skip reason
    (``category: detail``). ``frames``: full-resolution images by frame index."""
    st, o = ctx.st, ctx.opts
    a, b = run
    gray = frames[c]
    try:
        det = detect_board_lens(gray, ctx.camera, ctx.board, ctx.eo.detector_flags)
    except ExtractionError as err:
        raise ExtractionError(f"no board: {err}") from None
    if det.reproj_rms_px > ctx.eo.max_reproj_px:
        raise ExtractionError(f"no board: corner reprojection RMS {det.reproj_rms_px:.2f} px > "
                              f"{ctx.eo.max_reproj_px} px")
    tracked = [stills.track_corners(gray, det.corners, frames[i]) for i in (c - 1, c + 1)]
    move = stills.corner_motion(det.corners, tracked)
    if move > o.still_px:
        raise ExtractionError(f"corners moving: {move:.2f} px RMS to a neighbouring frame > {o.still_px} px")
    k = int(ctx.pairing.scan[c])
    if k < 0:
        raise ExtractionError(f"no scan: nearest scan {1000 * ctx.pairing.dt_s[c]:.1f} ms away > tolerance "
                              f"{1000 * ctx.pairing.tol_s:.1f} ms")
    try:
        scan, idx = _segment(st, k, det.T_cam_board, ctx.board, ctx.eo)
    except ExtractionError as err:
        raise ExtractionError(f"no segment: {err}") from None
    shift_m = _scan_still(ctx, run, c, k, scan.bearing[idx], scan.range[idx], det.T_cam_board)
    rec = {"frame": c, "image_stamp_ns": int(st.image_ns[c]), "scan_stamp_ns": int(st.scan_ns[k]), "scan": k,
           "dt_ms": 1000 * float(ctx.pairing.dt_s[c]), "corner_motion_px": move,
           "scan_shift_mm": 1000 * shift_m, "reproj_rms_px": det.reproj_rms_px, "run": [a, b],
           "T_cam_board": det.T_cam_board.tolist()}
    return BoardObservation(det.T_cam_board, ctx.board.outline, scan.points[idx]), rec


def _log_runs(log: list[dict], runs, motion, thr) -> None:
    for i, f in enumerate(log):
        f["reason"] = f"moving: thumbnail change {np.nan_to_num(motion[i]):.2f} (or to the next frame) > {thr:.2f}" \
            " grey levels (99.9th percentile)"
    for run in runs:
        tries = ", ".join(map(str, stills.run_tries(run)))
        for i in range(*run):
            log[i]["reason"] = f"duplicate: still run {run[0]}-{run[1] - 1}, frames {tries} stand for it"
    if len(log):
        log[0]["reason"] = log[-1]["reason"] = "moving: no neighbour on one side (first or last frame)"


RETRY = ("corners moving", "scan moving")  # reasons after which the next frame of the run is tried


def pick(ctx: _Ctx, motion: np.ndarray) -> tuple[list[dict], list[dict], list[BoardObservation], float]:
    """Every frame's log entry and the kept poses (module docstring of ``lidarcam.rig.stills``)."""
    st, o = ctx.st, ctx.opts
    thr = o.quiet_grey if o.quiet_grey > 0 else stills.quiet_threshold(motion)
    runs = stills.still_runs(motion, thr, o.min_run)
    log = [{"frame": i, "stamp_ns": int(t), "kept": False, "pose": None, "reason": ""}
           for i, t in enumerate(st.image_ns)]
    _log_runs(log, runs, motion, thr)
    cands, boards = [], []
    for run in runs:  # full-resolution frames are read again one run at a time, and only the kept one is held
        frames = _fetch(ctx.src, ctx.image_topic, st, [i for c in stills.run_tries(run) for i in (c - 1, c, c + 1)])
        for c in stills.run_tries(run):
            try:
                obs, rec = check_candidate(ctx, run, c, frames)
            except ExtractionError as err:
                log[c]["reason"] = str(err)
                if str(err).startswith(RETRY):
                    continue
                break
            rec["png"] = _png(frames[c])
            cands.append(rec)
            boards.append(obs)
            break
    kept_T: list[tuple[int, np.ndarray]] = []
    uniq = []
    for i in np.argsort([r["corner_motion_px"] for r in cands], kind="stable"):
        r = cands[i]
        dup = stills.too_close(np.asarray(r["T_cam_board"]), kept_T, ctx.board.centre, o)
        if dup is not None:
            log[r["frame"]]["reason"] = (f"same pose: as frame {dup[0]} ({dup[1]:.1f} deg < {o.min_angle_deg} deg "
                                         f"and {100 * dup[2]:.1f} cm < {100 * o.min_move_m:.0f} cm)")
            continue
        kept_T.append((r["frame"], np.asarray(r["T_cam_board"])))
        uniq.append(int(i))
    order, spread = stills.spread_order([boards[i] for i in uniq], np.array([cands[i]["corner_motion_px"]
                                                                             for i in uniq]), o.max_poses)
    chosen = sorted((uniq[j] for j in order), key=lambda i: cands[i]["frame"])
    for i in uniq:
        if i not in chosen:
            log[cands[i]["frame"]]["reason"] = (f"not needed: {o.max_poses} poses already spread the board normals "
                                                f"({spread:.1f} deg)")
    return log, [cands[i] for i in chosen], [boards[i] for i in chosen], spread


def _png(gray: np.ndarray) -> bytes:
    import cv2

    ok, buf = cv2.imencode(".png", gray)
    return buf.tobytes()


def _write(out: Path, camera: CameraModel, board_path: Path, st: Streams, poses: list[dict],
           scan_direction: str | None = None) -> None:
    from .bag import camera_yaml
    from .dataset import lidar_yaml

    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.yaml").write_text(camera_yaml(camera))
    shutil.copyfile(board_path, out / "board.yaml")
    if scan_direction is not None:
        (out / "lidar.yaml").write_text(lidar_yaml(scan_direction, "declared to lidarcam bag (--scan-direction)"))
    for n, p in enumerate(poses):
        name = f"{n:03d}"
        p["pose"] = name
        (out / f"{name}.png").write_bytes(p.pop("png"))
        np.savetxt(out / f"{name}.csv", np.column_stack([st.bearing, st.ranges[p["scan"]].astype(float)]),
                   delimiter=",", header="bearing_rad,range_m", comments="", fmt="%.9g")


def bag_to_dataset(bag, out, image_topic: str, scan_topic: str, board_path, *, camera_info_topic: str | None = None,
                   camera_path=None, opts: stills.PickOptions | None = None,
                   extract_opts: ExtractOptions | None = None, scan_direction: str | None = None) -> BagConversion:
    """Convert a recording into a dataset folder ``out`` (module docstring); returns what was done.

    ``scan_direction`` (``cw`` / ``ccw``, or None: nothing declared) is written into ``lidar.yaml``: the scans
    are written as the LaserScan messages count them (``angle_min + i angle_increment``), and a driver that counts
    clockwise without saying so is declared ``cw`` (the picking reads ranges only, so it does not depend on it).

    The camera comes from ``camera_info_topic`` or, when None, from ``camera_path`` (camera.yaml); the board from
    ``board_path`` (board.yaml). Raises BagError / DatasetError for a bad bag, topic or file.
    """
    opts, eo = opts or stills.PickOptions(), extract_opts or ExtractOptions()
    out, board_path = Path(out), Path(board_path)
    board = load_board(board_path)
    if camera_info_topic is None and camera_path is None:
        raise BagError("needs a camera: give --camera-info-topic or --camera camera.yaml", file=bag)
    with BagSource(bag) as src:
        camera = read_camera_info(src, camera_info_topic) if camera_info_topic else load_camera(camera_path)
        st = read_streams(src, image_topic, scan_topic, opts.thumb_width)
        if st.image_size != (camera.width, camera.height):
            raise BagError(f"image topic {image_topic!r}: images are {st.image_size[0]}x{st.image_size[1]} but the "
                           f"camera is {camera.width}x{camera.height}", file=src.path)
        motion = timesync.image_motion(st.thumbs)
        pairing, sync = _sync(st, motion, opts)
        ctx = _Ctx(src, image_topic, st, camera, board, opts, eo, pairing)
        log, poses, _, spread = pick(ctx, motion)
    _write(out, camera, board_path, st, poses, scan_direction)
    for p in poses:
        log[p["frame"]].update(kept=True, pose=p["pose"],
                               reason=f"kept: pose {p['pose']}, corners moved {p['corner_motion_px']:.2f} px, scan "
                                      f"{p['dt_ms']:+.1f} ms away, segment shift {p['scan_shift_mm']:.1f} mm")
    conv = BagConversion(out, len(st.image_ns), len(st.scan_ns), timesync.median_period(st.scan_ns), sync, poses,
                         log, spread)
    doc = {"source": str(bag), "image_topic": image_topic, "scan_topic": scan_topic,
           "camera_info_topic": camera_info_topic, "n_images": conv.n_images, "n_scans": conv.n_scans,
           "scan_period_s": conv.scan_period_s, "sync": sync, "options": asdict(opts),
           "normal_spread_deg": spread, "poses": poses, "frames": log}
    (out / "picking.json").write_text(json.dumps(doc, indent=1, default=float) + "\n")
    return conv
