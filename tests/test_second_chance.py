"""The search's second chance: when no candidate fits the duration limit but one came
close, guided profiles costed another way are tried (schedsyn.planner.search)."""

import numpy as np

from schedsyn import Limits, ThermalParams
from schedsyn.model import FirstOrderLag
from schedsyn.planner import ExperimentSpec
from schedsyn.planner import search as search_mod
from schedsyn.planner.guide import parallel_profiles
from schedsyn.planner.lp import LpStats


def test_profiles_costed_at_the_edge_speed_are_another_shape_within_the_same_limits():
    """Turns costed at the edge bins' speed give other profiles than the bound's costing
    (the second chance is worth trying only if they differ), still parallel ``sep``
    apart and within the chamber's reach."""
    spec = ExperimentSpec("W2", -30.0, 0.0, -40.0, 10.0)
    params, limits = ThermalParams(), Limits()
    sep = 0.102
    args = (spec, params, limits, {+1: 3, -1: 3}, sep, 0.9)
    mean = parallel_profiles(*args, edge="mean")
    speed = parallel_profiles(*args, edge="speed")
    assert mean is not None and speed is not None
    for d, top in ((+1, limits.rate_max_c_per_min), (-1, -limits.rate_min_c_per_min)):
        assert np.max(np.abs(speed[d][0] - mean[d][0])) > 0.02, d
        for faster, slower in zip(speed[d][:-1], speed[d][1:], strict=True):
            np.testing.assert_allclose(faster - slower, sep, atol=0.006)
        assert np.all(speed[d][0] < top) and np.all(speed[d][-1] > 0), d


def _candidates_tried(monkeypatch, spec, params, limits):
    tried = []
    real = search_mod.candidate_bands

    def spy(candidate, *args, **kwargs):
        tried.append(candidate)
        return real(candidate, *args, **kwargs)

    monkeypatch.setattr(search_mod, "candidate_bands", spy)
    found = search_mod.synthesise(spec, [params], limits, [FirstOrderLag(params)], None, LpStats())
    monkeypatch.undo()
    return found, tried


def test_second_chance_only_when_the_best_structure_nearly_fits(monkeypatch):
    """Two levels over [0, 4] degC: the usual candidates' shortest structure sets the
    mark. One segment less of budget and nothing usual fits, but nearly: the second
    chance's candidates are tried. With a sixth less they are not (no near miss)."""
    spec = ExperimentSpec("S", 0.0, 4.0, -5.0, 9.0, levels_required=2)
    params = ThermalParams()
    roomy = Limits(duration_max_min=400.0)
    found, tried = _candidates_tried(monkeypatch, spec, params, roomy)
    assert found.best is not None
    assert not any(c in search_mod.SECOND_CHANCE for c in tried)
    minutes = found.ctx.responses.edges_min[found.best[0].n_seg]

    near = Limits(duration_max_min=minutes - spec.segment_min)
    _, tried = _candidates_tried(monkeypatch, spec, params, near)
    assert any(c in search_mod.SECOND_CHANCE for c in tried)

    # 20 % over: still placed (the greedy runs on to 1.3x the limit), but not near
    far = Limits(duration_max_min=minutes / 1.2)
    found, tried = _candidates_tried(monkeypatch, spec, params, far)
    assert found.best is None and found.overrun is not None
    assert not any(c in search_mod.SECOND_CHANCE for c in tried)
