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
