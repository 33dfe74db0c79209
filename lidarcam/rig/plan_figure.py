"""The capture plan's picture: a top view of the lidar, the camera's frustum and the boards (captured and
proposed), and the predicted 1-sigma per axis against the number of boards."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib_core.data.observations import Observations
from calib_core.planning.capture import SIGMA_NAMES, Plan
from calib_core.planning.views import PlanRig

FRUSTUM_M = 7.0
"""Length (metres) of the camera's frustum edges in the top view."""
LABEL_MERGE_M = 0.4
"""Proposed boards whose centres lie closer than this (metres, top view) share one label ("1, 3, 5")."""


def label_groups(centres: np.ndarray, merge_m: float = LABEL_MERGE_M) -> list[tuple[np.ndarray, str]]:
    """One (position, text) per group of board centres (K,2) closer than ``merge_m``: the boards' 1-based numbers
    in order, at the group's first centre; every number once, no two labels closer than ``merge_m``."""
    groups: list[list[int]] = []
    for i, c in enumerate(centres):
        near = next((g for g in groups if np.linalg.norm(centres[g[0]] - c) < merge_m), None)
        if near is None:
            groups.append([i])
        else:
            near.append(i)
    return [(centres[g[0]], ", ".join(str(i + 1) for i in g)) for g in groups]


def _board_xy(T_lidar_board: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """(M,V+1,2) closed outlines of the boards in the lidar frame, top view (x, y)."""
    P = np.column_stack([outline, np.zeros(len(outline))])
    X = np.einsum("mij,vj->mvi", T_lidar_board[:, :3, :3], P) + T_lidar_board[:, None, :3, 3]
    return np.concatenate([X[:, :, :2], X[:, :1, :2]], axis=1)


def _frustum(ax, rig: PlanRig) -> None:
    cam, T = rig.camera, rig.T_lidar_cam
    corners = np.array([[0, 0], [cam.width - 1, 0], [cam.width - 1, cam.height - 1], [0, cam.height - 1]], float)
    rays = np.column_stack([(corners - cam.K[:2, 2]) / np.diag(cam.K)[:2], np.ones(4)])
    ends = (rays / np.linalg.norm(rays, axis=1, keepdims=True) * FRUSTUM_M) @ T[:3, :3].T + T[:3, 3]
    for e in ends:
        ax.plot([T[0, 3], e[0]], [T[1, 3], e[1]], color="0.6", lw=0.8)
    ax.plot(*T[:2, 3], "s", color="k", ms=5, label="camera")


def save_plan_figure(path, rig: PlanRig, plan: Plan, current: Observations | None = None) -> Path:
    """Write the plan's figure (PNG) to ``path``: top view (left) and predicted 1-sigma vs boards (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5))
    ax.plot(0, 0, "o", color="k", ms=6, label="lidar")
    _frustum(ax, rig)
    if current is not None and current.n_boards:
        T_lb = rig.T_lidar_cam[None] @ np.array([b.T_cam_board for b in current.boards])
        for i, xy in enumerate(_board_xy(T_lb, rig.outline)):
            ax.plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=1.5, label="captured" if i == 0 else None)
    outlines = _board_xy(plan.T_lidar_board, rig.outline)
    for i, xy in enumerate(outlines):
        ax.plot(xy[:, 0], xy[:, 1], color="tab:red", lw=1.5, label="proposed" if i == 0 else None)
    for c, text in label_groups(outlines[:, :-1].mean(axis=1) if len(outlines) else np.zeros((0, 2))):
        ax.annotate(text, c, textcoords="offset points", xytext=(8, 8), color="tab:red", fontsize=9,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.set_aspect("equal")
    ax.set_xlabel("lidar x (m)")
    ax.set_ylabel("lidar y (m)")
    ax.set_title("top view: lidar, camera frustum, boards")
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(alpha=0.3)
    preds = list(plan.after) + list(plan.extension)
    n = plan.current_n + 1 + np.arange(len(preds))
    S = np.array([p.sigma for p in preds])
    for j, name in enumerate(SIGMA_NAMES):
        scale = np.degrees(1.0) if j < 3 else 1000.0
        kw = {"ls": "-" if j < 3 else "--"}
        bx.plot(n, np.where(np.isfinite(S[:, j]), S[:, j] * scale, np.nan), label=name.replace("_", " ("
                ) + ")", **kw)
    bx.axvline(plan.current_n + len(plan.after), color="0.5", lw=0.8)
    bx.set_yscale("log")
    bx.set_xlabel("boards (captured + proposed, greedy order)")
    bx.set_ylabel("predicted 1-sigma (deg: solid; mm: dashed)")
    bx.set_title(f"criterion {plan.criterion}; target {plan.target[0]:g} deg, {plan.target[1]:g} mm"
                 + ("" if plan.to_target is None else f": {plan.to_target} boards"))
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
