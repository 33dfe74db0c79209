"""The paper's real experiment (Sec. 3.2, Fig. 8-9) on the public rigs: for each board count 3-8, seeded random
subsets of the usable boards, every method; theta_R and mu_t (docs/METHOD.md eq. 15) per method and board count
(Fig. 9), two methods' laser points on one image from 4 boards (Fig. 8), and the valid rate of each method against
the all-board answer of the best held-out method other than itself (within 8 deg / 0.8 m, and within 3 of that
answer's sigmas): Fig. 3a on real data. Rows are stored per data set (``subsets_<set>.csv``) and reused when the
data and settings match.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

import calib_core
from calib_core.data.io import observations_to_dict
from calib_core.data.observations import Observations
from calib_core.geometry.metrics import is_valid, pose_errors, sigma_rot_deg, sigma_trans_m
from calib_core.geometry.mounting import MountingPrior
from calib_core.geometry.transforms import rotvec_to_matrix
from lidarcam.rig.markdown import md_table

from ..summary.intervals import wilson_interval
from ..summary.tables import refusal_table, refusals, refused_axes

BOARD_COUNTS = (3, 4, 5, 6, 7, 8)
N_SUBSETS = 50
VALID_DEG, VALID_M = 8.0, 0.8
"""The paper's validity thresholds (docs/METHOD.md eq. 13-14)."""
SIGMAS = 3.0
"""The stricter validity: within this many of the reference answer's 1-sigma (rotation and translation)."""
PRIOR_METHOD = "lidarcam"
PRIOR_SIGMA_DEG, PRIOR_SIGMA_MM = 10.0, 50.0
"""The rough mounting guess the experiment also gives ``PRIOR_METHOD`` (``drawn_prior``): 1-sigma per axis, degrees
and millimetres, as a tape measure and a protractor give it."""
PRIOR_LABEL = f"{PRIOR_METHOD} + mounting prior"
"""How the rows of ``PRIOR_METHOD`` run with that guess are named (a row label, not a registered method)."""


def theta_mu(T: np.ndarray) -> tuple[float, float]:
    """eq. 15: ``theta_R = (180/pi) acos((trace R - 1)/2)`` (deg) and ``mu_t = |t|`` (m) of ``T_lidar_cam``."""
    c = np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0)
    return float(np.degrees(np.arccos(c))), float(np.linalg.norm(T[:3, 3]))


def subsets(name: str, n_boards: int, counts=BOARD_COUNTS, n: int = N_SUBSETS, seed: int = 0) -> list[tuple[int, ...]]:
    """``n`` random board subsets per count (sorted indices), seeded by ``seed`` and the data set's name."""
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    return [tuple(sorted(rng.choice(n_boards, k, replace=False).tolist())) for k in counts if k <= n_boards
            for _ in range(n)]


def drawn_prior(name: str, subset: tuple[int, ...], T_ref: np.ndarray, seed: int = 0) -> MountingPrior:
    """A user's rough guess of the mounting for one subset: ``T_ref`` (4,4, ``T_lidar_cam``) with a rotation error
    drawn from N(0, ``PRIOR_SIGMA_DEG``) about each axis (a rotation vector, applied on the left) and a translation
    error from N(0, ``PRIOR_SIGMA_MM``) along each, stated with those sigmas; seeded by ``seed``, the data set's
    name and the subset, so every run and worker draws the same guess."""
    rng = np.random.default_rng([seed, zlib.crc32(name.encode()), zlib.crc32(" ".join(map(str, subset)).encode())])
    w = rng.normal(0.0, np.radians(PRIOR_SIGMA_DEG), 3)
    dt = rng.normal(0.0, PRIOR_SIGMA_MM / 1000, 3)
    T = np.array(T_ref, float)
    T[:3, :3] = rotvec_to_matrix(w) @ T[:3, :3]
    T[:3, 3] += dt
    return MountingPrior(T, np.radians(PRIOR_SIGMA_DEG), PRIOR_SIGMA_MM / 1000)


def guesses_valid(name: str, df: pd.DataFrame, T_ref: np.ndarray, seed: int = 0) -> float:
    """The share of the subsets in ``df`` whose drawn guess (``drawn_prior``) is itself valid against ``T_ref``."""
    subs = [tuple(int(i) for i in str(s).split()) for s in df["subset"].unique()]
    ok = [is_valid(*pose_errors(drawn_prior(name, s, T_ref, seed).T_lidar_cam, T_ref), VALID_DEG, VALID_M)
          for s in subs]
    return float(np.mean(ok)) if ok else math.nan


def _run(obs: Observations, subset: tuple[int, ...], methods, prior: MountingPrior | None = None) -> list[dict]:
    out = []
    sub = obs.subset(list(subset))
    runs = [(m, m, None) for m in methods] + ([(PRIOR_LABEL, PRIOR_METHOD, prior)] if prior is not None else [])
    for label, m, p in runs:
        res = calib_core.calibrate(sub, m) if p is None else calib_core.calibrate(sub, m, prior=p)
        row = {"n_boards": len(subset), "subset": " ".join(map(str, subset)), "method": label, "ok": res.ok,
               "seconds": res.seconds, "theta_R_deg": math.nan, "mu_t_m": math.nan, "T": "",
               "refused_axes": "" if res.ok else " ".join(refused_axes(res.reason)), "cov": ""}
        if res.ok:
            row["theta_R_deg"], row["mu_t_m"] = theta_mu(res.T_lidar_cam)
            row["T"] = json.dumps(np.round(res.T_lidar_cam, 9).tolist())
            if res.covariance is not None:
                row["cov"] = cov_text(res.covariance)
        out.append(row)
    return out


ROW_COLUMNS = ("n_boards", "subset", "method", "ok", "seconds", "theta_R_deg", "mu_t_m", "T", "refused_axes", "cov")
"""The columns of a subset row (part of the stored rows' key: rows stored without one are recomputed).
``refused_axes``: the axes a refusal names as not determined (``summary.tables.refused_axes``), space-separated;
``cov``: the answer's 6x6 covariance (``cov_text``), empty without one."""


def cov_text(C: np.ndarray) -> str:
    """A 6x6 covariance as text: its upper triangle row by row, 7 significant digits, space-separated."""
    return " ".join(f"{v:.7g}" for v in np.asarray(C, float)[np.triu_indices(6)])


def cov_from_text(text) -> np.ndarray | None:
    """The 6x6 covariance of ``cov_text``; None for an empty or missing cell."""
    if not isinstance(text, str) or not text.strip():
        return None
    C = np.zeros((6, 6))
    C[np.triu_indices(6)] = [float(v) for v in text.split()]
    return C + np.triu(C, 1).T


def run_subsets(name: str, obs: Observations, methods, out: Path, n_jobs: int = 2, n: int = N_SUBSETS,
                seed: int = 0, T_prior: np.ndarray | None = None) -> pd.DataFrame:
    """Every method on every subset of ``subsets(...)``, and with ``T_prior`` (4,4) also ``PRIOR_METHOD`` given a
    rough guess drawn around it (``drawn_prior``, rows ``PRIOR_LABEL``); stored in ``out/subsets_<name>.csv`` with
    a key of the data and settings and of the library's code (``engine.fingerprint``), read back instead of rerun
    when it matches."""
    from joblib import Parallel, delayed

    from ..engine.fingerprint import package_hash

    prior = None if T_prior is None else [np.round(np.asarray(T_prior, float), 12).tolist(), PRIOR_METHOD,
                                          PRIOR_SIGMA_DEG, PRIOR_SIGMA_MM]
    key = hashlib.sha256(json.dumps([observations_to_dict(obs)["boards"], list(methods), n, seed,
                                     list(BOARD_COUNTS), package_hash("calib_core"), prior,
                                     list(ROW_COLUMNS)], sort_keys=True,
                                    default=str).encode()).hexdigest()[:16]
    path = out / f"subsets_{name}.csv"
    if path.exists():
        df = pd.read_csv(path, keep_default_na=False, na_values=[""])
        if len(df) and str(df["key"].iloc[0]) == key:
            print(f"  subsets: {len(df)} rows reused from {path.name}", flush=True)
            return df
    jobs = subsets(name, obs.n_boards, n=n, seed=seed)
    t0 = time.perf_counter()
    priors = [None if T_prior is None else drawn_prior(name, s, T_prior, seed) for s in jobs]
    parts = Parallel(n_jobs=n_jobs, batch_size=4)(delayed(_run)(obs, s, methods, p)
                                                  for s, p in zip(jobs, priors, strict=True))
    df = pd.DataFrame([r for p in parts for r in p])
    df.insert(0, "key", key)
    df.to_csv(path, index=False)
    print(f"  subsets: {len(jobs)} subsets x {len(methods)} methods in {time.perf_counter() - t0:.0f} s", flush=True)
    return df


def valid_columns(df: pd.DataFrame, T_ref: np.ndarray, sigma_rot_deg: float | None,
                  sigma_trans_m: float | None) -> pd.DataFrame:
    """``df`` with ``e_R_deg``, ``e_t_m`` against the reference answer and ``valid`` (8 deg / 0.8 m) and
    ``valid_3sigma`` (within ``SIGMAS`` of the reference's 1-sigma; False when it has none)."""
    df = df.copy()
    e = [pose_errors(np.array(json.loads(T)), T_ref) if ok and isinstance(T, str) and T else (math.nan, math.nan)
         for ok, T in zip(df["ok"], df["T"], strict=True)]
    df["e_R_deg"] = [float(a) for a, _ in e]
    df["e_t_m"] = [float(b) for _, b in e]
    df["valid"] = (df["e_R_deg"] < VALID_DEG) & (df["e_t_m"] < VALID_M)
    if sigma_rot_deg and sigma_trans_m:
        df["valid_3sigma"] = (df["e_R_deg"] < SIGMAS * sigma_rot_deg) & (df["e_t_m"] < SIGMAS * sigma_trans_m)
    else:
        df["valid_3sigma"] = False
    return df


def valid_table(df: pd.DataFrame, methods) -> list[str]:
    """Markdown: valid rate (8 deg / 0.8 m) with its 95% Wilson interval, and the rate within 3 sigmas, per method
    and board count."""
    counts = sorted(df["n_boards"].unique())
    rows = []
    for m in methods:
        d = df[df["method"] == m]
        cells = []
        for k in counts:
            dk = d[d["n_boards"] == k]
            lo, hi = wilson_interval(int(dk["valid"].sum()), len(dk))
            cells.append(f"{100 * dk['valid'].mean():.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] / "
                         f"{100 * dk['valid_3sigma'].mean():.0f}%")
        rows.append([f"`{m}`", *cells])
    return md_table(["method", *(f"{k} boards" for k in counts)], rows, "l" + "r" * len(counts))


def fig9(df: pd.DataFrame, methods, path: Path, title: str) -> None:
    """Box plots of theta_R and mu_t (eq. 15) per method and board count (the paper's Fig. 9)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    counts = sorted(df["n_boards"].unique())
    fig = Figure(figsize=(2.2 * len(methods), 5.2))
    FigureCanvasAgg(fig)
    for r, (col, label) in enumerate((("theta_R_deg", "theta_R (deg)"), ("mu_t_m", "mu_t (m)"))):
        for c, m in enumerate(methods):
            ax = fig.add_subplot(2, len(methods), r * len(methods) + c + 1)
            d = df[(df["method"] == m) & df["ok"].astype(bool)]
            data = [d[d["n_boards"] == k][col].dropna().to_numpy() for k in counts]
            ax.boxplot([x if len(x) else [np.nan] for x in data], tick_labels=[str(k) for k in counts],
                       showfliers=True, flierprops={"markersize": 2})
            if r == 0:
                ax.set_title(m, fontsize=8)
            if c == 0:
                ax.set_ylabel(label, fontsize=8)
            if r == 1:
                ax.set_xlabel("boards", fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


TITLE_PT = 8
"""Font size (points) of Fig. 8's title, which wraps to the image's width above it."""


def fig8(gray: np.ndarray, camera, board, answers: dict[str, np.ndarray], path: Path, title: str):
    """Two methods' laser points (the board's scan) on one image through their extrinsics (the paper's Fig. 8),
    the title wrapped above the image at its width; returns the figure. ``board``: the ``BoardObservation`` of the
    pose shown; ``answers``: method -> ``T_lidar_cam``."""
    import textwrap

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from calib_core.geometry.transforms import invert_T
    from lidarcam.rig.report import project_scan

    h, w = gray.shape[:2]
    line_px = TITLE_PT * 100 / 72  # one text line at 100 dpi
    lines = textwrap.wrap(title, width=max(20, int(w / (0.6 * line_px))))
    head = int(math.ceil(1.4 * line_px * len(lines) + 8))
    fig = Figure(figsize=(w / 100, (h + head) / 100), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, h / (h + head)))
    ax.imshow(gray, cmap="gray", vmin=0, vmax=255)
    ax.set_axis_off()
    for (m, T), colour in zip(answers.items(), ("red", "cyan", "yellow"), strict=False):
        uv, ok = project_scan(camera, invert_T(T), board.scan)
        ax.scatter(uv[ok, 0], uv[ok, 1], s=6, c=colour, label=m)
    ax.legend(loc="lower right", fontsize=7)
    fig.text(0.01, 1 - 4 / (h + head), "\n".join(lines), fontsize=TITLE_PT, va="top")
    fig.savefig(path)
    return fig


def own_nees(name: str, obs: Observations, method: str = PRIOR_METHOD, n: int = N_SUBSETS,
             seed: int = 0) -> pd.DataFrame:
    """``method`` on all boards and on each subset of ``subsets(...)``, judged against its own all-board answer:
    one row per subset with ``ok``, the errors ``e_R_deg``/``e_t_m``, ``valid`` (8 deg / 0.8 m), ``valid_3sigma``
    (within ``SIGMAS`` of the all-board answer's 1-sigma, as ``valid_columns``), ``nees`` (the subset's covariance
    against the all-board answer, ``geometry.metrics.nees``; the all-board answer's own error left out, so the
    NEES is an upper bound where the subset shares boards with it), ``own_3sigma`` (within ``SIGMAS`` of the
    subset's own 1-sigma, rotation and translation) and the verdict's warnings that flag a weak choice
    (``weak``: runners-up or a fold)."""
    from calib_core.geometry.metrics import nees

    ref = calib_core.calibrate(obs, method)
    if not ref.ok:
        raise RuntimeError(f"{name}: {method} refuses all {obs.n_boards} boards: {ref.reason}")
    rows = []
    for s in subsets(name, obs.n_boards, n=n, seed=seed):
        res = calib_core.calibrate(obs.subset(list(s)), method)
        row = {"set": name, "n_boards": len(s), "subset": " ".join(map(str, s)), "ok": res.ok,
               "e_R_deg": math.nan, "e_t_m": math.nan, "nees": math.nan, "own_3sigma": False,
               "weak": any(w.startswith("weakly decided") or "fold" in w for w in res.warnings),
               "reason": "" if res.ok else str(res.reason)[:120]}
        if res.ok:
            row["e_R_deg"], row["e_t_m"] = pose_errors(res.T_lidar_cam, ref.T_lidar_cam)
            if res.covariance is not None:
                row["nees"] = nees(res.T_lidar_cam, ref.T_lidar_cam, res.covariance)
            if res.sigma_rot_deg and res.sigma_trans_mm:
                row["own_3sigma"] = bool(row["e_R_deg"] < SIGMAS * res.sigma_rot_deg and
                                         row["e_t_m"] < SIGMAS * res.sigma_trans_mm / 1000)
        rows.append(row)
    df = pd.DataFrame(rows)
    df["valid"] = (df["e_R_deg"] < VALID_DEG) & (df["e_t_m"] < VALID_M)
    df["valid_3sigma"] = (df["e_R_deg"] < SIGMAS * ref.sigma_rot_deg) & \
        (df["e_t_m"] < SIGMAS * ref.sigma_trans_mm / 1000)
    return df


def own_nees_table(df: pd.DataFrame) -> list[str]:
    """Markdown of ``own_nees`` rows: per set and board count the NEES median (answered subsets), the valid rate,
    the rate within 3 of the all-board answer's sigmas and within 3 of the subset's own, and the weak-choice
    warnings' rate among the invalid answers."""
    rows = []
    for (s, k), d in df.groupby(["set", "n_boards"]):
        bad = d[d["ok"] & ~d["valid"]]
        rows.append([s, str(k), f"{np.nanmedian(d['nees']):.1f}", f"{100 * d['ok'].mean():.0f}%",
                     f"{100 * d['valid'].mean():.0f}%", f"{100 * d['valid_3sigma'].mean():.0f}%",
                     f"{100 * d['own_3sigma'].mean():.0f}%",
                     f"{int(bad['weak'].sum())}/{len(bad)}"])
    return md_table(["set", "boards", "NEES median", "answered", "valid", "within 3 sigma (all-board's)",
                     "within 3 own sigma", "invalid with a weak-choice warning"], rows, "llrrrrrr")


def nees_column(df: pd.DataFrame, T_ref: np.ndarray) -> pd.Series:
    """Each row's NEES against ``T_ref`` (4,4, ``T_lidar_cam``; ``geometry.metrics.nees`` with the row's own
    covariance, ``cov``); NaN where the row has no answer or no covariance."""
    from calib_core.geometry.metrics import nees

    out = [nees(np.array(json.loads(T)), T_ref, C) if ok and isinstance(T, str) and T and
           (C := cov_from_text(c)) is not None else math.nan
           for ok, T, c in zip(df["ok"].astype(bool), df["T"], df.get("cov", pd.Series("", index=df.index)),
                               strict=True)]
    return pd.Series(out, index=df.index, dtype=float)


def uncertainty_table(df: pd.DataFrame, method: str, T_own: np.ndarray | None) -> tuple[list[str], pd.DataFrame]:
    """(Markdown, its rows) for ``method``'s subset rows of ``df`` (with ``valid``, ``valid_3sigma`` from
    ``valid_columns``): per board count, refusals naming an axis (``summary.tables.refusals``), the NEES
    median against ``T_own`` (``method``'s all-board answer; none without it), the valid rate, the rate within
    3 sigmas and their ratio."""
    d = df[df["method"] == method]
    d = d.assign(nees=nees_column(d, np.asarray(T_own, float)) if T_own is not None else math.nan)
    r = refusals(d, method)
    by = d.groupby("n_boards")
    r["valid_rate"] = r["n_boards"].map(by["valid"].mean()).astype(float)
    r["within_3sigma_rate"] = r["n_boards"].map(by["valid_3sigma"].mean()).astype(float)
    r["ratio_3sigma_valid"] = r["within_3sigma_rate"] / r["valid_rate"].where(r["valid_rate"] > 0)
    own = own_sigma_columns(d, T_own).groupby(d["n_boards"])
    r["valid_own_rate"] = r["n_boards"].map(own["valid_own"].mean()).astype(float)
    r["own_3sigma_rate"] = r["n_boards"].map(own["own_3sigma"].mean()).astype(float)
    r["ratio_own_3sigma_valid"] = r["own_3sigma_rate"] / r["valid_own_rate"].where(r["valid_own_rate"] > 0)

    def pct(col):
        return [f"{100 * v:.0f}%" if np.isfinite(v) else "-" for v in r[col]]

    def ratio(col):
        return [f"{v:.2f}" if np.isfinite(v) else "-" for v in r[col]]

    return refusal_table(r, {"valid": pct("valid_rate"), "within 3 sigma": pct("within_3sigma_rate"),
                             "3 sigma / valid": ratio("ratio_3sigma_valid"),
                             "valid vs own": pct("valid_own_rate"), "within 3 own sigma": pct("own_3sigma_rate"),
                             "own 3 sigma / valid vs own": ratio("ratio_own_3sigma_valid")}), r


def own_sigma_columns(d: pd.DataFrame, T_own: np.ndarray | None) -> pd.DataFrame:
    """Per row of ``d`` (``ok``, ``T``, ``cov``) against ``T_own`` (the method's own all-board answer): ``valid_own``
    (within 8 deg / 0.8 m of it) and ``own_3sigma`` (within ``SIGMAS`` of the row's own 1-sigma, rotation and
    translation, ``geometry.metrics.sigma_rot_deg`` / ``sigma_trans_m`` of the row's covariance; False without
    one); both False where the row has no answer or there is no ``T_own``."""
    valid, within = [], []
    for ok, T, c in zip(d["ok"].astype(bool), d["T"], d.get("cov", pd.Series("", index=d.index)), strict=True):
        if not (ok and isinstance(T, str) and T and T_own is not None):
            valid.append(False)
            within.append(False)
            continue
        e_R, e_t = pose_errors(np.array(json.loads(T)), np.asarray(T_own, float))
        C = cov_from_text(c)
        valid.append(bool(e_R < VALID_DEG and e_t < VALID_M))
        within.append(C is not None and bool(e_R < SIGMAS * sigma_rot_deg(C) and e_t < SIGMAS * sigma_trans_m(C)))
    return pd.DataFrame({"valid_own": valid, "own_3sigma": within}, index=d.index)
