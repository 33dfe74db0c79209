"""The result's typed parts (``CalibrationResult.outcome``): each noise figure named by its source, the covariance
model as an enum, the verdict and consensus parts; the same parts after a ``lidarcam.result/1`` round trip; the
range residual RMS before and after a refinement, in the summary."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import make_observations

from calib_core import calibrate
from calib_core.data.outcome import (
    CovarianceModel,
    CovariancePart,
    InfoParts,
    JointFitPart,
    NoiseModel,
    ObservationsPart,
    ResidualRmsPart,
    VerdictPart,
)
from calib_core.data.result import CalibrationResult


@pytest.mark.parametrize("seed", range(3))
def test_lidarcam_parts_name_each_noise_figure_and_survive_the_file(seed, tmp_path):
    obs = make_observations(np.random.default_rng(900 + seed), 6, 0.02)
    r = calibrate(obs)
    assert r.ok
    o = r.outcome
    noise = (o.noise.scan_lines_m, o.noise.trimmed_m, o.noise.verdict_spread_m)
    assert all(v is not None and 0.005 < v < 0.08 for v in noise), noise   # 20 mm noise, named by source
    assert o.covariance.model is CovarianceModel.RANGE_ONLY             # no corners in these scenes
    assert o.verdict is not None and o.verdict.consistent
    assert o.consensus.boards_used == tuple(range(6)) and o.consensus.hypotheses > 0
    r.save(tmp_path / "r.json")
    back = CalibrationResult.load(tmp_path / "r.json").outcome
    assert back.noise == o.noise and back.covariance.model is o.covariance.model
    assert back.consensus.boards_used == o.consensus.boards_used and back.verdict == o.verdict
    assert back.residual_rms == pytest.approx(o.residual_rms)


def test_ml_refinement_never_raises_the_range_rms_and_the_summary_says_both():
    """``X+ml`` minimises the range residuals from its base's answer: the RMS at its answer is at most the RMS at
    the start (its base's answer), and the summary of an answered call prints both."""
    answered = 0
    for seed in range(6):
        obs = make_observations(np.random.default_rng(700 + seed), 6, 0.02)
        r = calibrate(obs, "vasconcelos+ml")
        rms = r.info["residual_rms"]
        assert rms["answer_m"] <= rms["start_m"] * (1 + 1e-9)
        base = calibrate(obs, "vasconcelos")
        assert rms["start_m"] == pytest.approx(base.info["residual_rms"]["answer_m"], rel=1e-9)
        if r.ok:
            answered += 1
            line = next(s for s in r.summary_lines() if s.startswith("range residual RMS"))
            assert f"{1000 * rms['start_m']:.1f} mm at the start" in line
            assert f"{1000 * rms['answer_m']:.1f} mm at the answer" in line
    assert answered >= 3


def test_a_plugin_s_own_covariance_wording_is_kept_as_other():
    r = CalibrationResult("x", True, np.eye(4), covariance=np.eye(6) * 1e-6, info={"covariance_model": "my lab's"})
    assert r.outcome.covariance.model is CovarianceModel.OTHER and r.outcome.covariance.model_text == "my lab's"
    assert r.outcome.noise.to_dict() is None and "noise" not in r.to_dict()


def test_info_parts_become_entries_in_one_place_and_override_a_base_method_s():
    """``InfoParts.to_info``: a part left out gives no entry; every part overrides the base method's entry of the
    same name (a derived method's covariance replaces its base's), the base's other entries stay; the typed parts
    read back through ``Outcome`` as they went in."""
    base = {"cost": 3.0, "covariance_model": CovarianceModel.RANGE_ONLY, "board_dispersion": {"widened": False},
            "warnings": ["from the base"]}
    cov = CovariancePart(np.eye(6), CovarianceModel.JOINT, "exact", conditioning=0.5, bend={"moved": 1.0})
    fit = JointFitPart(0.4, 0.02, 0.41, 0.021, 10.0, 7, True)
    info = InfoParts(base=base, covariance=cov, joint=fit, noise_model=NoiseModel("per-beam range noise", 0.02),
                     warnings=["mine"]).to_info()
    assert info["covariance_model"] is CovarianceModel.JOINT and info["covariance"] is cov.matrix
    assert info["board_dispersion"] == {"widened": False} and info["cost"] == 3.0       # the base's, not replaced
    assert info["covariance_bend"] == {"moved": 1.0} and info["conditioning"] == 0.5
    assert info["joint_iterations"] == 7 and info["range_sigma_m"] == 0.02 and info["warnings"] == ["mine"]
    assert not {"prior", "alternatives", "degeneracy", "board_error", "base_T_lidar_cam"} & set(info)
    o = CalibrationResult("m", True, np.eye(4), covariance=np.eye(6), info=info).outcome
    assert o.covariance.model is CovarianceModel.JOINT and o.noise_model.name == "per-beam range noise"
    assert InfoParts(base=base).to_info() == base and "warnings" not in InfoParts().to_info()


@pytest.mark.parametrize("method", ["lidarcam", "vasconcelos+ml"])
def test_calibrate_s_own_entries_are_parts_that_read_back_as_they_went_in(method):
    """``calibrate`` adds the residual RMS, the verdict and the observations' fingerprint as ``InfoParts``: each
    entry read back as its part gives the same entry, the fingerprint last; the method's start and covariance
    are not entries."""
    obs = make_observations(np.random.default_rng(950), 5, 0.02)
    info = calibrate(obs, method).info
    v = VerdictPart.from_info(info)
    assert v.to_dict() == info["verdict"] and v.sigma_m > 0 and len(v.boards) == 5
    assert ResidualRmsPart(**info["residual_rms"]).to_dict() == info["residual_rms"]
    assert info["residual_rms"]["answer_m"] < 0.05 and list(info)[-1] == "observations"
    assert ObservationsPart(**info["observations"]).to_dict() == info["observations"]
    assert "start_T_lidar_cam" not in info and "covariance" not in info
