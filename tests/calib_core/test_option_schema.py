"""Options declared once, on the method (``registry.accepted_options``): ``calibrate`` and the experiments' config
validation accept and refuse the same names for every registered method, the derived ``X+s`` variants of every
base, the ablations and a plugin; an unknown option is refused by name with the accepted ones listed."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import make_observations

from calib_core import CalibrationError, calibrate, get_method
from calib_core.registry import METHODS, SUFFIXES, Method, accepted_options, register
from experiments.config.validate import ConfigError, check_methods, method_options


def _every_method() -> list[str]:
    bases = [n for n in METHODS if "+" not in n]
    return sorted({*METHODS, *(f"{b}+{s}" for b in bases for s in SUFFIXES)})


def _candidate_names() -> set[str]:
    names = {"bogus_option", "f_scale", "min_conditioning"}
    for n in _every_method():
        names |= set(accepted_options(get_method(n)) or ())
    return names


def _calibrate_refusal(obs, name: str, key: str) -> str | None:
    try:
        calibrate(obs, name, **{key: object()})
    except CalibrationError as err:
        if "option" in str(err) and repr(key) in str(err):
            return str(err)
    except Exception:  # an accepted option given a nonsense value fails inside the method: accepted by the schema
        return None
    return None


def _validation_refusal(name: str, key: str) -> str | None:
    try:
        check_methods([name], {name: {key: 1}})
    except ConfigError as err:
        return str(err)
    return None


@pytest.mark.parametrize("name", _every_method())
def test_calibrate_and_validation_accept_the_same_names(name):
    """A name is refused by ``calibrate`` exactly when the validation refuses it, with the same reason; and
    ``method_options`` is the registry's schema."""
    from calib_core import registry

    obs = make_observations(np.random.default_rng(7), 4)
    m = get_method(name)
    accepted = registry.accepted_options(m)
    assert method_options(name) == (None if accepted is None else set(accepted) | {"verdict"})
    for key in sorted(_candidate_names()):
        by_calibrate, by_config = _calibrate_refusal(obs, name, key), _validation_refusal(name, key)
        assert (by_calibrate is None) == (by_config is None), (name, key, by_calibrate, by_config)
        if by_config is not None:
            assert by_calibrate in by_config
        if accepted is not None:
            assert (by_config is None) == (key in accepted and key not in registry.RENAMED_OPTIONS), (name, key)


def test_the_joint_suffix_takes_its_own_options_not_the_refinement_s():
    """``X+joint`` takes ``corner_sigma_px`` and refuses ``f_scale_m`` (the refinement's) in both places."""
    obs = make_observations(np.random.default_rng(3), 5)
    assert "corner_sigma_px" in method_options("zhang_pless_linear+joint")
    assert "f_scale_m" not in method_options("zhang_pless_linear+joint")
    assert "f_scale_m" in method_options("zhang_pless_linear+ml")
    with pytest.raises(CalibrationError, match=r"unknown option 'f_scale_m'; it takes .*corner_sigma_px"):
        calibrate(obs, "zhang_pless_linear+joint", f_scale_m=0.05)
    with pytest.raises(ConfigError, match="f_scale_m"):
        check_methods(["zhang_pless_linear+joint"], {"zhang_pless_linear+joint": {"f_scale_m": 0.05}})


def test_a_plugin_s_options_are_its_function_s_named_keywords(monkeypatch):
    """A plugin that declares no options takes its function's named keywords, in both places."""
    from calib_core import registry

    def lab(obs, *, gain: float = 1.0):
        return np.eye(4), np.eye(4)[None], {}

    monkeypatch.setattr(registry, "METHODS", dict(registry.METHODS))
    register(Method("lab_schema_test", lab, 3, "a lab", "identity", origin="tests"))
    assert accepted_options(get_method("lab_schema_test")) == {"gain"}
    assert method_options("lab_schema_test+ml") >= {"gain", "f_scale_m"}
    with pytest.raises(CalibrationError, match="unknown option 'gainn'; it takes gain"):
        calibrate(make_observations(np.random.default_rng(1), 4), "lab_schema_test", gainn=2.0)


def test_only_methods_that_take_a_prior_accept_one():
    takers = {n for n, m in METHODS.items() if m.takes_prior}
    assert takers == {"lidarcam"}
    assert not get_method("lidarcam+ml").takes_prior
