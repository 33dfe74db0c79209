"""The peng2022 ablations, the explain experiment files, and a tiny explain run."""

from __future__ import annotations

import pytest

from calib_core import METHODS, calibrate
from calib_core.methods.ablations import ABLATIONS, INVARIANT, SCALE_ONLY
from simulate import SimOptions, generate

N_PROBLEMS = 30


@pytest.fixture(scope="module")
def problems():
    return [generate(SimOptions(n_boards=4 + k % 3, noise_mm=(20.0, 30.0)[k % 2]), seed=11, trial=k)
            for k in range(N_PROBLEMS)]


def test_ablations_registered():
    for name in ABLATIONS:
        assert name in METHODS and METHODS[name].min_boards == METHODS["peng2022"].min_boards
    assert set(INVARIANT) | set(SCALE_ONLY) <= set(ABLATIONS)


def test_invariant_variants_choose_as_peng(problems):
    """nonorm (a per-board constant), betamax/betanone (one positive scale of all exponents) keep the argmax."""
    for obs in problems:
        base = calibrate(obs, "peng2022")
        for name in (*INVARIANT, *SCALE_ONLY):
            r = calibrate(obs, name)
            assert r.ok == base.ok
            if base.ok:
                assert r.info["chosen"] == base.info["chosen"], name


def test_other_variants_run(problems):
    for obs in problems[:6]:
        for name in ABLATIONS:
            r = calibrate(obs, name)
            assert r.ok or r.reason
            if r.ok:
                assert r.T_lidar_cam.shape == (4, 4)


SENS = {"sens_tilt": ("scene.max_tilt_deg", 4), "sens_board": ("scene.board_size_m", 4),
        "sens_spread": ("scene.bearing_spread_deg", 4), "sens_focal": ("camera.focal_px", 3),
        "sens_extrinsic": ("scene.extrinsic_rot_deg", 4), "sens_pixel": ("noise.pixel_noise_px", 3),
        "sens_res": ("lidar.lidar_res_deg", 2)}


@pytest.mark.parametrize("experiment", ["ablation", *SENS])
def test_explain_experiments_compose(experiment):
    from experiments.config.sweeps import experiment_cells

    cells = experiment_cells(experiment, ["n_trials=2"])
    n_values = 1 if experiment == "ablation" else SENS[experiment][1]
    assert len(cells) == 4 * n_values
    assert {(c.sim["n_boards"], c.sim["noise_mm"]) for c in cells} == {(4, 20.0), (4, 30.0), (6, 20.0), (6, 30.0)}
    if experiment == "ablation":
        assert set(cells[0].methods) == {"vasconcelos", "peng2022", *ABLATIONS}
    else:
        assert cells[0].methods == ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022", "lidarcam")
        field = SENS[experiment][0].split(".")[1]
        assert len({c.sim[field] for c in cells}) == n_values
    if experiment == "sens_pixel":
        assert cells[0].sim["pose_mode"] == "pixel"


def test_tiny_explain_run(tmp_path):
    from experiments.paper.explain import explain

    (tmp_path / "paper").mkdir()
    (tmp_path / "paper" / "REPORT.md").write_text("# paper\n")
    r = explain(ablation_trials=3, sens_trials=2, results_dir=str(tmp_path), n_jobs=1,
                experiments=["ablation", "sens_res"], progress=False)
    out = tmp_path / "explain"
    for name in ("summary_ablation.csv", "trials_ablation.csv", "ablation_paired.csv", "summary_sens_res.csv",
                 "fit_to_paper.csv", "figures/sens_res.png", "REPORT.md"):
        assert (out / name).exists(), name
    text = r["report"].read_text()
    for section in ("## Where the gain comes from", "## What the paper did not say", "## A fit to the paper"):
        assert section in text
    assert "explain/REPORT.md" in (tmp_path / "paper" / "REPORT.md").read_text()
