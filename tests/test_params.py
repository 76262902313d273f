import dataclasses

import pytest

from schedsyn import Limits, ParameterError, ThermalParams


def test_defaults_are_the_documented_ones():
    p, lim = ThermalParams(), Limits()
    assert (p.tau_s, p.dt0_c) == (2400.0, 3.0)
    assert (lim.rate_min_c_per_min, lim.rate_max_c_per_min) == (-1.0, 3.0)
    assert (lim.chamber_min_c, lim.chamber_max_c) == (-70.0, 80.0)
    assert (lim.device_min_c, lim.device_max_c) == (-52.0, 62.0)
    assert lim.duration_max_min == 540.0
    assert (lim.start_c, lim.end_c, lim.end_tol_c, lim.t_init_c) == (20.0, 20.0, 0.5, 20.0)


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ThermalParams().tau_s = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    "changes, name",
    [
        ({"rate_min_c_per_min": 3.0}, "rate_min_c_per_min"),
        ({"rate_min_c_per_min": float("nan")}, "rate_min_c_per_min"),
        ({"chamber_min_c": 90.0}, "chamber_min_c"),
        ({"device_min_c": 70.0}, "device_min_c"),
        ({"duration_max_min": 0.0}, "duration_max_min"),
        ({"end_tol_c": -1.0}, "end_tol_c"),
        ({"start_c": -100.0}, "start_c"),
    ],
)
def test_invalid_limits_name_the_parameter(changes, name):
    with pytest.raises(ParameterError, match=name):
        Limits(**changes)


@pytest.mark.parametrize(
    ("build", "name"),
    [
        (lambda: ThermalParams(2400, "3"), "dt0_c"),
        (lambda: ThermalParams("2400", 3.0), "tau_s"),
        (lambda: ThermalParams(True, 3.0), "tau_s"),
        (lambda: ThermalParams(2400.0, None), "dt0_c"),
        (lambda: Limits(chamber_min_c="-70"), "chamber_min_c"),
        (lambda: Limits(duration_max_min=True), "duration_max_min"),
        (lambda: Limits(end_tol_c=[0.5]), "end_tol_c"),
    ],
)
def test_non_numbers_are_refused_at_construction(build, name):
    """A string or bool must fail here, not later with a TypeError inside simulate."""
    with pytest.raises(ParameterError, match=f"{name} must be a number"):
        build()


def test_numbers_of_any_real_type_are_stored_as_floats():
    import numpy as np

    p = ThermalParams(np.int64(2400), np.float32(3.0))
    assert type(p.tau_s) is float and type(p.dt0_c) is float
    assert p == ThermalParams(2400.0, 3.0)
    lim = Limits(chamber_min_c=-60)
    assert type(lim.chamber_min_c) is float


def test_bin_grid_refuses_bools():
    from schedsyn.grid import BinGrid

    with pytest.raises(ParameterError, match="lo_c"):
        BinGrid(True, 5)


def test_diagnose_settings_refuse_strings():
    from schedsyn.discrepancy import DiagnoseSettings

    with pytest.raises(ParameterError, match="fit_step_s must be a number"):
        DiagnoseSettings(fit_step_s="3")
    with pytest.raises(ParameterError, match="bic_margin must be a number"):
        DiagnoseSettings(bic_margin="15")
