"""Guided bands (schedsyn.planner.guide) ask for no speed the chamber cannot give.

The chamber limits cap the gradient at every temperature, ``g = (Tk + dT0 - T) / tau``:
heating at most ``(ceiling + dT0 - T) / tau``, cooling at most ``(T - floor - dT0) / tau``
(the planning model, written out here, not taken from the planner). A band whose floor
reaches that cap cannot be followed, and every structure built on it gets stuck.
"""

import dataclasses

import numpy as np
import pytest

from schedsyn import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec
from schedsyn.planner.guide import guided_bands

# a 25-degC region with the ceiling (heating) or the floor (cooling) 11.6 degC beyond its
# far edge, counting dT0: the fast band's floor in the middle of the region reached the
# limit's speed there (0.954 degC/min at 11 degC, where the ceiling allows 0.953)
PARAMS = ThermalParams(tau_s=1800.0, dt0_c=3.8)
SPEC = ExperimentSpec("near-limit", 3.0, 28.0, -7.0, 28.0, levels_required=3)
CEILING = dataclasses.replace(Limits(), rate_min_c_per_min=-2.0, chamber_max_c=35.8)
FLOOR = dataclasses.replace(Limits(), rate_min_c_per_min=-3.0, chamber_min_c=-12.4)


def _chamber_speed(direction: int, temp_c: np.ndarray, limits: Limits) -> np.ndarray:
    tau_min = PARAMS.tau_s / 60.0
    if direction > 0:
        return (limits.chamber_max_c + PARAMS.dt0_c - temp_c) / tau_min
    return (temp_c - limits.chamber_min_c - PARAMS.dt0_c) / tau_min


@pytest.mark.parametrize("limits, direction", [(CEILING, +1), (FLOOR, -1)])
@pytest.mark.parametrize("rate_share", [0.8, 0.9])
def test_no_guided_band_asks_for_a_speed_the_chamber_limit_denies(limits, direction, rate_share):
    n_by_dir = {direction: 2, -direction: 1}
    bands = guided_bands(SPEC, [PARAMS], limits, n_by_dir, 0.04, rate_share, chamber_share=True)
    assert bands is not None
    for band in bands[direction]:
        knots = np.asarray(band.knots_c)
        cap = _chamber_speed(direction, knots, limits)
        lo = np.asarray(band.lo_c_per_min)
        # at least 5 % of the limit's speed to spare at every knot
        assert np.all(lo <= 0.95 * cap), (band.rank, np.round(lo - 0.95 * cap, 3))
