"""Where the plan puts boards: the grid's orientation (8x5 or 5x8) does not change it, proposed boards stand at
distinct places, and a plan that needs many boards says what limits it."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.observations import BoardObservation, Observations
from calib_core.model.board_error import BoardErrorScale
from calib_core.planning.capture import REPEAT_ANGLE_DEG, plan_capture, plan_summary, separation_m
from calib_core.planning.observed import plan_from_observations
from lidarcam.rig.plan_figure import LABEL_MERGE_M
from lidarcam.rig.plan_rig import load_plan_rig
from simulate import SimOptions, generate

RIG_FILE = Path(__file__).resolve().parents[3] / "lidarcam" / "rig" / "plan_template.yaml"
QUARTER = np.array([[0.0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])   # board' -> board


def _turned(obs: Observations) -> Observations:
    """The same boards with the grid written the other way round (board x and y swapped by a quarter turn)."""
    boards = [BoardObservation(b.T_cam_board @ QUARTER, b.outline @ QUARTER[:2, :2], b.scan, b.corners_px,
                               np.column_stack([b.corners_board[:, :2], np.zeros(len(b.corners_board))])
                               @ QUARTER[:3, :3], outline_kind=b.outline_kind) for b in obs.boards]
    return Observations(tuple(boards), obs.T_lidar_cam_true, dict(obs.meta), obs.camera, obs.board_range_sigma_m)


TRANSPOSE = np.array([[0.0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]])   # board' -> board


def _transposed(obs: Observations) -> Observations:
    """The same boards with the grid written the other way round as a detector that keeps the corners' order
    row-major over the transposed grid gives them: board x and y swapped, z flipped (the board's normal now points
    the other way), the corners re-ordered."""
    boards = []
    for b in obs.boards:
        order = np.lexsort((b.corners_board[:, 1], b.corners_board[:, 0]))      # rows of the transposed grid
        cb = np.column_stack([b.corners_board[order][:, [1, 0]], np.zeros(len(order))])
        boards.append(BoardObservation(b.T_cam_board @ TRANSPOSE, b.outline[::-1][:, ::-1], b.scan,
                                       b.corners_px[order], cb, outline_kind=b.outline_kind))
    return Observations(tuple(boards), obs.T_lidar_cam_true, dict(obs.meta), obs.camera, obs.board_range_sigma_m)


@pytest.mark.parametrize("seed, offset_mm, other", [(3, 0.0, _turned), (4, 0.0, _turned), (3, 5.0, _turned),
                                                    (5, 0.0, _transposed)])
def test_the_grids_orientation_does_not_change_the_plan(seed, offset_mm, other):
    """With and without a per-board systematic error (the file's stated offset, which the plan holds); the grid
    turned a quarter (as the project's detector gives 5x8 for 8x5) or transposed (the normal flipped)."""
    obs = generate(SimOptions(n_boards=8, pose_mode="pixel", board_squares_x=8, board_squares_y=5, max_roll_deg=10.0,
                              noise_mm=10.0, lidar_board_offset_mm=offset_mm), seed)
    plans = []
    for o in (obs, other(obs)):
        r = calibrate(o)
        assert r.ok
        plans.append(plan_from_observations(o, r.T_lidar_cam, 4, covariance=r.covariance, info=r.info).plan)
    a, b = plans
    assert a.board_error.active == (offset_mm > 0) == b.board_error.active
    assert b.current.rot_sigma_deg == pytest.approx(a.current.rot_sigma_deg, rel=1e-3)
    for pa, pb in zip(a.after, b.after, strict=True):
        assert pb.rot_sigma_deg == pytest.approx(pa.rot_sigma_deg, rel=0.1)
        assert pb.trans_sigma_mm == pytest.approx(pa.trans_sigma_mm, rel=0.1)
    assert (a.to_target is None) == (b.to_target is None)
    if a.to_target is not None:
        assert b.to_target == pytest.approx(a.to_target, rel=0.1)


def test_proposed_boards_stand_at_distinct_places():
    rig = load_plan_rig(RIG_FILE)
    plan = plan_capture(rig, 6)
    c = plan.T_lidar_board[:, :3, :3] @ np.r_[rig.outline.mean(axis=0), 0.0] + plan.T_lidar_board[:, :3, 3]
    apart = np.linalg.norm(c[:, None] - c[None], axis=-1)[np.triu_indices(len(c), 1)]
    assert apart.min() >= separation_m(rig) - 1e-9 and apart.min() >= LABEL_MERGE_M


def test_a_plan_of_many_boards_says_what_limits_it():
    """Without a per-board systematic error the noise limits it: the boards in all with half of each noise."""
    rig = replace(load_plan_rig(RIG_FILE), board_error=BoardErrorScale())
    plan = plan_capture(rig, 3)
    assert not plan.limited_by_systematic
    assert plan.to_target is None or plan.to_target > 30
    line = next(ln for ln in plan.summary_lines(rig) if ln.startswith("what limits it"))
    counts = [int(n) for n in __import__("re").findall(r"\): (\d+)", line)]
    assert len(counts) == 2 and all(n < (plan.to_target or 10**9) for n in counts)


@pytest.mark.parametrize("offset_mm, limited", [(0.0, False), (20.0, True)])
def test_a_target_the_per_board_systematic_error_puts_out_of_reach_is_said_in_one_line(offset_mm, limited):
    rig = replace(load_plan_rig(RIG_FILE), board_error=BoardErrorScale(offset_mm / 1000.0, 0.0))
    plan = plan_capture(rig, 3, target=(0.05, 2.0))
    assert plan.to_target is None and plan.limited_by_systematic == limited
    lines = plan.summary_lines(rig)
    said = [ln for ln in lines if "limited by the per-board systematic error" in ln and ln.startswith("the target")]
    assert len(said) == (1 if limited else 0)
    if limited:
        assert "20.0 mm offset" in said[0] and not any("not within the planner's limit" in ln for ln in lines)
        assert "limited by the per-board systematic error" in plan_summary(plan)
        assert "not reached within" not in plan_summary(plan)


def test_the_rig_files_systematic_error_defaults_to_the_calibrations_prior(tmp_path):
    from calib_core.refine.systematic import DEFAULT_PRIOR

    assert load_plan_rig(RIG_FILE).board_error == DEFAULT_PRIOR
    text = RIG_FILE.read_text().replace("  range_sigma_mm: 20.0",
                                        "  range_sigma_mm: 20.0\n  board_offset_mm: 4\n  board_tilt_mm: 0", 1)
    (tmp_path / "rig.yaml").write_text(text)
    rig = load_plan_rig(tmp_path / "rig.yaml")
    assert rig.board_error == BoardErrorScale(0.004, 0.0)
    bare = replace(rig, board_error=BoardErrorScale())
    # the term costs information: the same boards predict a larger 1-sigma with it
    assert plan_capture(rig, 4).after[-1].rot_sigma_deg > plan_capture(bare, 4).after[-1].rot_sigma_deg


def _repeats(plan, rig) -> int:
    """Pairs of proposed boards within the separation of each other whose normals are within REPEAT_ANGLE_DEG."""
    T = plan.T_lidar_board
    c = T[:, :3, :3] @ np.r_[rig.outline.mean(axis=0), 0.0] + T[:, :3, 3]
    near = np.linalg.norm(c[:, None] - c[None], axis=-1) < separation_m(rig)
    same = np.abs(T[:, :3, 2] @ T[:, :3, 2].T) > np.cos(np.radians(REPEAT_ANGLE_DEG))
    return int(np.triu(near & same, 1).sum())


def test_a_compact_workspace_gets_distinct_poses_not_near_repeats():
    """A workspace with room for few places (as a captured set's, a metre away): after every place has a board,
    the next ones turn or lean differently from the boards already there instead of repeating them."""
    base = load_plan_rig(RIG_FILE)
    rig = replace(base, workspace=replace(base.workspace, distance_m=(3.0, 3.6), bearing_deg=(-6.0, 6.0)))
    plan = plan_capture(rig, 8)
    T = plan.T_lidar_board
    c = T[:, :3, :3] @ np.r_[rig.outline.mean(axis=0), 0.0] + T[:, :3, 3]
    assert np.linalg.norm(c[:, None] - c[None], axis=-1)[np.triu_indices(8, 1)].min() < separation_m(rig)  # shared
    assert _repeats(plan, rig) == 0


def _behind(obs: Observations) -> Observations:
    """The same rig with the lidar turned half a turn about its z axis: the boards stand behind it, around 180 deg
    (as on EdenShin's rig), where the bearings run past +-180."""
    half = np.diag([-1.0, -1.0, 1.0, 1.0])
    boards = tuple(replace(b, scan=-b.scan) for b in obs.boards)
    return Observations(boards, half @ obs.T_lidar_cam_true, dict(obs.meta), obs.camera, obs.board_range_sigma_m)


def test_boards_behind_the_lidar_plan_as_in_front():
    """Turning the lidar about its own z axis does not change the plan: the workspace follows the boards across
    +-180 deg (not the whole circle between the two ends)."""
    obs = generate(SimOptions(n_boards=8, pose_mode="pixel", max_roll_deg=10.0, noise_mm=10.0), 6)
    plans = []
    for o in (obs, _behind(obs)):
        r = calibrate(o)
        assert r.ok
        plans.append(plan_from_observations(o, r.T_lidar_cam, 4, covariance=r.covariance, info=r.info).plan)
    a, b = plans
    assert np.all(np.abs(b.poses[:, 1]) > 90.0)
    for pa, pb in zip(a.after, b.after, strict=True):
        assert pb.rot_sigma_deg == pytest.approx(pa.rot_sigma_deg, rel=0.1)
        assert pb.trans_sigma_mm == pytest.approx(pa.trans_sigma_mm, rel=0.1)
