"""The planner: bands by construction, plans checked by independent re-simulation."""

import dataclasses
import math
import pickle

import numpy as np
import pytest
from independent import chamber_knots, levels_per_bin, ode_trajectories, table_check
from run_once import once_per_run
from scipy.integrate import solve_ivp

from schedsyn import (
    BinGrid,
    Limits,
    Programme,
    ThermalParams,
    coverage_report,
    read_steps,
    simulate,
)
from schedsyn.errors import InfeasiblePlanError, ParameterError
from schedsyn.planner import (
    BAND_SAFETY_C_PER_MIN,
    DESIGNS,
    ExperimentSpec,
    check_programme,
    explain_shortfall,
    make_bands,
    plan_experiment,
    turning_speed,
)
from schedsyn.planner.core import EFFORT_S, operator_programme
from schedsyn.planner.lp import ROBUST_SLACK_C_PER_MIN, LpStats
from schedsyn.planner.polish import polish
from schedsyn.planner.robust import box_note, search_robust, verify_robust

SMALL = dict(
    name="S",
    working_lo_c=-10.0,
    working_hi_c=0.0,
    approx_lo_c=-20.0,
    approx_hi_c=10.0,
    levels_required=3,
)
SMALL_LIMITS = Limits(duration_max_min=300.0)


@pytest.fixture(scope="module")
def small_plan():
    return plan_experiment(ExperimentSpec(**SMALL), limits=SMALL_LIMITS)


@pytest.mark.parametrize("design", sorted(DESIGNS))
@pytest.mark.parametrize("region", [(-50, -30, -52, -20), (30, 60, 20, 60), (-30, 0, -40, 10)])
@pytest.mark.parametrize("direction", [-1, +1])
def test_bands_are_delta_apart_at_every_temperature(region, direction, design):
    spec = ExperimentSpec("W", *region)
    delta = spec.delta_c_per_min
    bands = make_bands(
        spec,
        3,
        direction,
        delta + BAND_SAFETY_C_PER_MIN,
        [ThermalParams()],
        Limits(),
        design=DESIGNS[design],
    )
    t = np.linspace(region[0] - 0.5, region[1] + 0.5, 500)
    lows = [b.bounds(t)[0] for b in bands]
    highs = [b.bounds(t)[1] for b in bands]
    for r in range(len(bands)):
        assert np.all(highs[r] >= lows[r] - 1e-12)
    for r in range(len(bands) - 1):
        assert np.all(lows[r + 1] - highs[r] >= delta - 1e-9)
    # heating and cooling passes are delta apart: every band keeps |g| >= delta / 2
    assert np.all(lows[0] >= delta / 2 - 1e-12)


@pytest.mark.parametrize("v0", [0.1, 0.3, 0.8])
def test_turning_speed_matches_a_simulated_stop(v0):
    """From the speed turning_speed allows, reversing at the chamber rate stops the device
    within the room: checked by integrating the lag ODE with scipy."""
    tau_min, rate = 40.0, 1.0
    # distance travelled from v0 to standstill under U = -rate (heating device, cooling air)
    sol = solve_ivp(
        lambda t, y: [y[1], (-rate - y[1]) / tau_min],
        (0, 400),
        [0.0, v0],
        events=lambda t, y: y[1],
        max_step=0.1,
        rtol=1e-9,
        atol=1e-12,
    )
    room = float(sol.y_events[0][0][0])
    assert turning_speed(room, rate, tau_min, turn_fraction=1.0) == pytest.approx(v0, rel=1e-4)
    # with less of the rate available the allowed speed is lower
    assert turning_speed(room, rate, tau_min, turn_fraction=0.8) < v0


def test_direct_probe_lp_matches_cvxpy():
    """The search's probe LPs go to Clarabel without cvxpy: same optimum as through cvxpy."""
    import cvxpy as cp

    from schedsyn.model import FirstOrderLag
    from schedsyn.planner import Scenario
    from schedsyn.planner.lp import Context, LpStats, Responses, SubLP

    spec = ExperimentSpec(**SMALL)
    p = ThermalParams()
    stats = LpStats()
    ctx = Context(
        spec, SMALL_LIMITS, Responses([Scenario(p, FirstOrderLag(p))], 24, 5.0, SMALL_LIMITS), stats
    )
    lp = SubLP(ctx, np.zeros(0), 24, extra=1)
    lp.chamber()
    lp.device()
    lp.chamber_end(20.0)
    # the device must reach -5 degC at sample 60 while the extra column bounds g there
    lp.le(lp.scen[0][0][60], -5.0 - lp.scen[0][1][60])
    lp.le(lp.scen[0][2][100], -lp.scen[0][3][100], {0: -1.0})
    cost = np.zeros(lp.n + 1)
    cost[-1] = 1.0
    x_direct = lp.solve_direct(cost, l1_weight=1e-3)
    x_cvx = lp.solve(lambda v: v[-1] + 1e-3 * cp.norm1(v[:-1]))
    assert x_direct is not None and x_cvx is not None
    obj = lambda x: x[-1] + 1e-3 * np.abs(x[:-1]).sum()  # noqa: E731
    assert obj(x_direct) == pytest.approx(obj(x_cvx), abs=1e-5)
    # an impossible target is reported as infeasible by both
    lp.le(lp.scen[0][0][30], -60.0 - lp.scen[0][1][30])
    assert lp.solve_direct(cost) is None
    assert lp.solve(lambda v: v[-1]) is None
    # ... and counted as infeasible, not as a solver failure
    assert (stats.infeasible, stats.failed) == (2, 0)
    assert stats.solves == 4


def test_bands_respect_the_chamber_floor_near_the_cold_edge():
    spec = ExperimentSpec("W1", -50, -30, -52, -20)
    p = ThermalParams()
    bands = make_bands(spec, 3, -1, 0.062, [p], Limits(chamber_min_c=-60.0))
    g_floor = (-60.0 + p.dt0_c - (-50.5)) / p.tau_min  # most negative g at -50.5 degC
    assert bands[-1].bounds(-50.5)[1] <= -g_floor + 1e-9


def test_small_plan_is_complete_within_limits(small_plan):
    plan, lim = small_plan, SMALL_LIMITS
    assert plan.complete, plan.notes
    prog = plan.programme
    assert prog.total_min <= lim.duration_max_min
    assert np.allclose(prog.durations_min, np.round(prog.durations_min))
    tk = prog.boundary_temps_c
    assert np.allclose(tk * 10, np.round(tk * 10), atol=1e-6)
    assert tk[0] == pytest.approx(20.0) and abs(tk[-1] - 20.0) <= lim.end_tol_c
    assert np.all(prog.rates_c_per_min <= lim.rate_max_c_per_min + 1e-9)
    assert np.all(prog.rates_c_per_min >= lim.rate_min_c_per_min - 1e-9)
    assert tk.min() >= lim.chamber_min_c and tk.max() <= lim.chamber_max_c
    assert plan.steps <= plan.spec.max_steps
    assert np.all(np.abs(np.diff(prog.rates_c_per_min)) > 1e-9)  # equal rates merged


def _ode_trajectory(prog, params, dt_min=0.1):
    """Independent simulation of a step table: solve_ivp on the ODE, segment by segment."""
    tau = params.tau_s / 60.0
    t_all, temp_all, grad_all = [], [], []
    temp, tk = 20.0, prog.start_c
    start = 0.0
    for dur, rate in zip(prog.durations_min, prog.rates_c_per_min, strict=True):
        n = int(round(dur / dt_min))
        t_eval = start + dt_min * np.arange(n + 1)
        sol = solve_ivp(
            lambda t, x, r=rate, s0=start, k0=tk: [(k0 + r * (t - s0) + params.dt0_c - x[0]) / tau],
            (start, start + dur),
            [temp],
            t_eval=t_eval,
            rtol=1e-10,
            atol=1e-10,
        )
        tk_eval = tk + rate * (t_eval - start)
        keep = slice(0, -1)  # the end sample starts the next segment
        t_all.append(t_eval[keep])
        temp_all.append(sol.y[0][keep])
        grad_all.append(((tk_eval + params.dt0_c - sol.y[0]) / tau)[keep])
        temp, tk, start = sol.y[0][-1], tk + rate * dur, start + dur
    t_all.append([start])
    temp_all.append([temp])
    grad_all.append([(tk + params.dt0_c - temp) / tau])
    return np.concatenate(t_all), np.concatenate(temp_all), np.concatenate(grad_all)


def test_exported_table_reproduces_the_reported_coverage(small_plan, tmp_path):
    plan = small_plan
    path = plan.programme.to_csv(tmp_path / "steps.csv")
    prog = read_steps(path, SMALL_LIMITS)
    grid = BinGrid(plan.spec.working_lo_c, plan.spec.working_hi_c)
    traj = simulate(prog, plan.params)
    rep = coverage_report(traj.t_c, traj.g_c_per_min, grid, plan.spec.levels_required)
    assert np.array_equal(rep.levels, plan.coverage.levels)
    # and with separate code: the ODE integrated by scipy from the table
    _, temp, grad = _ode_trajectory(prog, plan.params)
    rep_ode = coverage_report(temp, grad, grid, plan.spec.levels_required)
    assert rep_ode.complete
    assert temp.min() >= SMALL_LIMITS.device_min_c and temp.max() <= SMALL_LIMITS.device_max_c


ROBUST_BOX = dict(robust_tau_s=(2200.0, 2600.0), robust_dt0_c=(2.0, 4.0))

#: The robust request's region: [-6, 0] degC at 2 levels in 200 min plans ROBUST_BOX in
#: about 8 s (SMALL, 10 degC at 3 levels in 300 min, took 20-30 s for the same checks).
#: Not narrower: the nominal plan of [-4, 0] degC already holds on the whole box, so a
#: planner that planned the box centre only went unnoticed by the re-simulation; the
#: nominal plan of [-6, 0] degC does not (12 % of the box grid short).
ROBUST_SMALL = dict(SMALL, working_lo_c=-6.0, approx_lo_c=-16.0, levels_required=2)
ROBUST_LIMITS = Limits(duration_max_min=200.0)


#: ROBUST_SMALL for ROBUST_BOX exactly as `schedsyn plan --working -6 0 --approx -16 10
#: --levels 2 --duration-max-min 200 --robust-tau-s 2200:2600 --robust-dt0-c 2:4` asks the
#: planner (tests/test_cli_plan.py), named as the CLI names it: (spec, params, limits,
#: keywords)
SMALL_ROBUST_REQUEST = (
    ExperimentSpec(**dict(ROBUST_SMALL, name="plan")),
    ThermalParams(),
    ROBUST_LIMITS,
    {
        "model": None,
        **ROBUST_BOX,
        "progress": None,
        "effort_s": EFFORT_S,
        "shorten": False,
        "end_soak": False,
    },
)


def small_robust_once(tmp_path_factory, worker_id):
    """The planner's answer to SMALL_ROBUST_REQUEST, planned once per test run:
    tests/test_cli_plan.py's robust test asks the planner the very same request."""
    spec, params, limits, kwargs = SMALL_ROBUST_REQUEST
    return once_per_run(
        tmp_path_factory,
        worker_id,
        "small-robust-plan",
        lambda: plan_experiment(spec, params, limits, **kwargs),
    )


@pytest.fixture(scope="module")
def small_robust_plan(tmp_path_factory, worker_id):
    return small_robust_once(tmp_path_factory, worker_id)


@pytest.fixture(scope="module")
def small_robust_nominal_plan():
    """The nominal plan of the robust request's spec and limits (no box)."""
    spec, params, limits, _ = SMALL_ROBUST_REQUEST
    return plan_experiment(spec, params, limits)


def test_robust_plan_holds_across_its_box_by_independent_resimulation(small_robust_plan, tmp_path):
    """One programme for the whole box: the exported table, integrated by scipy at points
    between and beyond the planner's own 9 x 7 check grid, covers the region everywhere."""
    plan = small_robust_plan
    assert plan.complete, plan.notes
    assert plan.box_check["holds"] and plan.box_check["grid_points"] >= 25 * 19
    prog = read_steps(plan.programme.to_csv(tmp_path / "robust.csv"), ROBUST_LIMITS)
    grid = BinGrid(plan.spec.working_lo_c, plan.spec.working_hi_c)
    for tau_s in (2200.0, 2325.0, 2475.0, 2600.0):
        for dt0_c in (2.0, 2.7, 3.6, 4.0):
            p = ThermalParams(tau_s=tau_s, dt0_c=dt0_c)
            _, temp, grad = _ode_trajectory(prog, p)
            rep = coverage_report(temp, grad, grid, plan.spec.levels_required)
            assert rep.complete, (tau_s, dt0_c, rep.summary())
            assert temp.max() <= ROBUST_LIMITS.device_max_c
            assert temp.min() >= ROBUST_LIMITS.device_min_c


def test_robust_plan_reports_its_scenarios_and_spaces_levels_wider(
    small_robust_nominal_plan, small_robust_plan
):
    """A robust plan carries its box check and scenarios; its bands are further apart, so
    its levels are spaced at least as wide as the nominal plan's (the same request
    without the box)."""
    nominal = small_robust_nominal_plan
    assert nominal.box_check is None
    assert small_robust_plan.coverage_0p1.coverage >= nominal.coverage_0p1.coverage
    assert len(small_robust_plan.scenarios) == 7  # box centre + 3 tau x 2 dT0


def test_a_nominal_plan_that_holds_on_the_box_spares_the_inner_searches(monkeypatch, tmp_path):
    """[-10, 0] degC at 2 levels in 120 min, box tau 2100..2700 s x dT0 2..4 degC: the
    search finds no programme for the whole box (it places every scenario's windows from
    the box centre), yet the nominal plan with the widest margins holds at every grid
    point. That plan is checked before the box's inner half and quarter, which are then not
    searched; the plan is complete for the box and its notes say why, not that no
    programme was found. Coverage over the 9 x 7 grid is re-made by scipy from the
    exported table (tests/independent.py)."""
    from schedsyn.planner import robust

    searched = []
    inner = robust.synthesise

    def spy(spec, params_list, *args, **kwargs):
        searched.append((spec.objective, len(params_list)))
        return inner(spec, params_list, *args, **kwargs)

    monkeypatch.setattr(robust, "synthesise", spy)
    box = dict(robust_tau_s=(2100.0, 2700.0), robust_dt0_c=(2.0, 4.0))
    spec = ExperimentSpec("H", -10.0, 0.0, -20.0, 10.0, levels_required=2)
    plan = plan_experiment(spec, limits=Limits(duration_max_min=120.0), **box)
    assert searched[0][1] > 1 and searched[1:] == [("margin", 1)], searched
    assert plan.box_check["holds"] and plan.complete
    assert plan.robust_fallback == "nominal point"
    assert not any(n.startswith("FALLBACK") for n in plan.notes), plan.notes
    assert any("holds at all 475 points" in n for n in plan.notes), plan.notes
    assert not any("one parameter only" in n for n in plan.notes), plan.notes
    taus, dt0s = np.meshgrid(
        np.linspace(*box["robust_tau_s"], 9), np.linspace(*box["robust_dt0_c"], 7), indexing="ij"
    )
    knots_t, knots_tk = chamber_knots(plan.programme.to_csv(tmp_path / "h.csv"))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, taus.ravel(), dt0s.ravel())
    for i in range(taus.size):
        assert (levels_per_bin(temp[i], grad[i], -10.0, 0.0, 0.05) >= 2).all(), i


def test_a_robust_plan_at_the_reported_delta_is_checked_once_per_delta():
    """A robust plan for delta 0.1 degC/min (the second separation every report counts
    at) failed with "deltas_c_per_min has repeated values: (0.1, 0.1)" from its own box
    check (judge's helper): the check counts each separation once."""
    spec = ExperimentSpec("D", -4.0, 0.0, -14.0, 10.0, levels_required=2, delta_c_per_min=0.1)
    plan = plan_experiment(
        spec,
        ThermalParams(dt0_c=2.5),
        Limits(duration_max_min=150.0),
        robust_tau_s=(2300.0, 2500.0),
        robust_dt0_c=(2.0, 3.0),
    )
    assert plan.box_check is not None and plan.box_check["grid_points"] == 25 * 19
    assert plan.complete == plan.box_check["holds"]


def test_a_box_over_tau_only_says_dt0_is_taken_as_exactly_nominal():
    """A box given for tau alone plans for dT0 exactly at its nominal value: legitimate,
    but a user who meant a box over both (and left out one option) must be told, not left
    with a plan whose "holds" claim silently covers a zero-width dT0 range (red team)."""
    spec = ExperimentSpec("H", -4.0, 0.0, -14.0, 10.0, levels_required=2)  # ~1 s
    params = ThermalParams(tau_s=2400.0, dt0_c=2.5)
    plan = plan_experiment(
        spec, params, Limits(duration_max_min=120.0), robust_tau_s=(2300.0, 2500.0)
    )
    notes = [n for n in plan.notes if "one parameter only" in n]
    assert len(notes) == 1, plan.notes
    assert "dT0 is taken as exactly its nominal 2.5 degC" in notes[0]
    assert "--robust-dt0-c" in notes[0]


def test_the_effort_limit_skips_the_robust_boxs_inner_rungs():
    """A wide box's own search ran 19 min and each inner box 10 min more (red team,
    [12, 27] degC, tau 1500-2100 s x dT0 0-3 degC), with --effort-s 20: the inner boxes are
    optional once the nominal plan is in hand and get effort_s of work of their own, so a
    spent effort limit cuts them and the notes say so (the request of the test below,
    where they are searched in full at the default effort)."""
    limits = Limits(duration_max_min=75.0)
    box = dict(robust_tau_s=(1800.0, 3000.0), robust_dt0_c=(0.0, 6.0))
    spec = ExperimentSpec("T", -2.0, 0.0, -12.0, 10.0, levels_required=2)
    said: list[str] = []
    plan = plan_experiment(spec, limits=limits, progress=said.append, effort_s=1e-9, **box)
    assert not plan.complete
    assert any("checking the nominal plan" in m for m in said)
    # the later rungs get effort_s of work of their own: the first (the inner half: the
    # bands fitted, so no narrower slack is tried) is cut at its first candidate, the
    # quarter not begun
    first = "the robust box's inner half"
    assert not any("held within" in m for m in said), said
    # the ramp rung's budget scales with effort_s: so small a limit skips it
    assert not any("searching ramp programmes" in m for m in said), said
    assert any("trying its inner half" in m for m in said), said
    assert not any("trying its inner quarter" in m for m in said), said
    fallback = [n for n in plan.notes if n.startswith("FALLBACK")]
    assert len(fallback) == 1 and "the search found no single programme" in fallback[0]
    assert f"stopped at its effort limit before finishing {first}" in fallback[0]
    assert any(
        "effort limit, effort_s = 1e-09" in n and f"{first} was not searched to the end" in n
        for n in plan.notes
    ), plan.notes


def test_too_wide_a_robust_box_says_which_part_is_covered(tmp_path):
    """A box too wide for the time limit: the planner falls back (inner half or quarter of
    the box, else the nominal point), never calls the plan complete, and names the part
    of the box it covers. Its box figures are re-made with separate code: the exported
    table integrated by scipy at every point of the 9 x 7 box grid and counted plainly
    (tests/independent.py), not with the planner's own sweep. A 2 degC region at 2 levels
    in 75 min: every rung of the fallback ladder is searched in seconds (SMALL at 3 levels
    in 240 min took over two minutes, [-5, 0] degC in 90 min 30 s, for the same checks)."""
    limits = Limits(duration_max_min=75.0)
    box = dict(robust_tau_s=(1800.0, 3000.0), robust_dt0_c=(0.0, 6.0))
    spec = ExperimentSpec("T", -2.0, 0.0, -12.0, 10.0, levels_required=2)
    said: list[str] = []
    plan = plan_experiment(spec, limits=limits, progress=said.append, **box)
    assert not plan.complete
    # the nominal plan with the widest margins does not hold on so wide a box: the inner
    # boxes are searched after it
    assert any("checking the nominal plan" in m for m in said)
    # at the default effort the ramp rung is searched (in vain), before the inner boxes
    ramp = [i for i, m in enumerate(said) if "searching ramp programmes" in m]
    inner = [i for i, m in enumerate(said) if "trying its inner half" in m]
    assert ramp and inner and ramp[0] < inner[0], said
    assert any("inner" in n or "nominal point" in n for n in plan.notes), plan.notes
    check = plan.box_check
    assert not check["holds"] and check["grid_points"] == 25 * 19
    # every (tau, dT0) of the 25 x 19 grid (ends included), integrated together
    taus, dt0s = np.meshgrid(
        np.linspace(*box["robust_tau_s"], 25),
        np.linspace(*box["robust_dt0_c"], 19),
        indexing="ij",
    )
    knots_t, knots_tk = chamber_knots(plan.programme.to_csv(tmp_path / "s.csv"))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, taus.ravel(), dt0s.ravel())
    cov = np.array(
        [np.mean(levels_per_bin(temp[i], grad[i], -2.0, 0.0, 0.05) >= 2) for i in range(taus.size)]
    ).reshape(taus.shape)
    assert np.mean(cov >= 1.0) == pytest.approx(check["full_share"])
    assert cov.min() == pytest.approx(check["worst"]["coverage"]) and cov.min() < 1.0
    # the report names the nominal point (grid point tau 2400 s, dT0 3 degC) and the fallback
    doc = plan.to_json_dict()
    assert doc["coverage_nominal"] == pytest.approx(cov[12, 9])
    assert doc["coverage_nominal"] > cov.min()
    assert doc["robust_fallback"] in ("inner half", "inner quarter", "nominal point")
    fallback = [n for n in plan.notes if n.startswith("FALLBACK")]
    # its search finding none proves nothing: the note must not say none fits
    assert len(fallback) == 1 and "not a proof that none exists" in fallback[0]
    assert "no programme fits" not in " ".join([*plan.notes, *said])
    i, j = np.unravel_index(np.argmin(cov), cov.shape)
    assert cov[
        int(np.argmin(np.abs(taus[:, 0] - check["worst"]["tau_s"]))),
        int(np.argmin(np.abs(dt0s[0, :] - check["worst"]["dt0_c"]))),
    ] == pytest.approx(cov[i, j])
    part = check["covered_box"]
    if part is not None:  # the named part of the box is covered at every grid point in it
        inside = (
            (taus >= part["tau_s_range"][0])
            & (taus <= part["tau_s_range"][1])
            & (dt0s >= part["dt0_c_range"][0])
            & (dt0s <= part["dt0_c_range"][1])
        )
        assert inside.sum() == part["n_points"] and (cov[inside] >= 1.0).all()
        assert f"{part['tau_s_range'][0]:g}..{part['tau_s_range'][1]:g} s" in plan.notes[-1]


def _box_coverage(programme, tmp_path, region, levels, tau_s, dt0_c):
    """Coverage at every point of a 25 x 19 grid over the box, the exported step table
    integrated by scipy and counted plainly (tests/independent.py)."""
    taus, dt0s = np.meshgrid(np.linspace(*tau_s, 25), np.linspace(*dt0_c, 19), indexing="ij")
    knots_t, knots_tk = chamber_knots(programme.to_csv(tmp_path / "box.csv"))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, taus.ravel(), dt0s.ravel())
    return np.array(
        [
            np.mean(levels_per_bin(t, g, *region, 0.05) >= levels)
            for t, g in zip(temp, grad, strict=True)
        ]
    )


def test_a_robust_box_around_the_start_temperature_is_planned_whole(tmp_path):
    """[20, 22] degC holds the start temperature: every scenario begins the first sweep's
    turnaround inside the region, and a scenario's window was looked for from there, so
    none was found and every such box fell back (red team: [20, 24] degC, dT0 2..4 degC,
    75 % at its worst point, where a hand-made table covered the box). A scenario's window
    now starts where it passes the start edge after it was first beyond it: the whole box
    is planned, and holds at every point of the dense grid by independent integration."""
    spec = ExperimentSpec("B", 20.0, 22.0, 10.0, 32.0, levels_required=2)
    box = dict(robust_tau_s=(2300.0, 2500.0), robust_dt0_c=(2.0, 4.0))
    plan = plan_experiment(spec, ThermalParams(dt0_c=3.0), Limits(duration_max_min=150.0), **box)
    assert plan.complete and plan.to_json_dict()["robust_fallback"] is None, plan.notes
    cov = _box_coverage(plan.programme, tmp_path, (20.0, 22.0), 2, *box.values())
    assert cov.min() == 1.0
    assert plan.box_check["holds"] and plan.box_check["full_share"] == 1.0


def test_a_wide_dt0_range_turns_the_low_scenarios_round_beyond_the_edges_too(tmp_path):
    """dT0 1..5 degC: the device at the box's low end sits 2 degC below the centre's, so a
    sweep placed for the centre, which turns round just past an edge, turns the low
    scenarios round before it (red team: [10, 14] degC at 4 levels fell back, 42 % at
    its worst point, where a hand-made table of rate-limit ramps covered the box). The
    reference is now placed as far beyond the edges as the scenarios fall short: the
    whole box is planned within 5 reference seconds of effort (without it the search
    spent them and fell back), and holds on the dense grid by independent integration."""
    spec = ExperimentSpec("W", 10.0, 13.0, 0.0, 23.0, levels_required=4)
    box = dict(robust_tau_s=(2000.0, 2800.0), robust_dt0_c=(1.0, 5.0))
    plan = plan_experiment(spec, limits=Limits(duration_max_min=400.0), effort_s=5.0, **box)
    assert plan.complete and plan.to_json_dict()["robust_fallback"] is None, plan.notes
    cov = _box_coverage(plan.programme, tmp_path, (10.0, 13.0), 4, *box.values())
    assert cov.min() == 1.0


def test_a_robust_box_with_no_room_for_the_default_slack_is_searched_at_a_narrower_one(
    tmp_path,
):
    """Five levels within 0.25 degC/min of cooling: the bands spaced for the default slack
    (each scenario 0.05 degC/min outside its band) leave no room for them, and the box
    fell back to a part of itself (red team: [40, 48] degC at 6 levels with the chamber
    cooling at 0.6 degC/min, 87.5 % at the worst point). The same box is searched again
    with the scenarios held closer to their bands; the levels stay delta apart in every
    scenario (the bands are twice the slack further apart), which the dense grid checks by
    independent integration. (The nominal plan with the widest margins is told not to
    hold, as it would on a wider box: plan_experiment takes it here where it holds.)"""
    spec = ExperimentSpec(
        "N",
        -2.0,
        0.0,
        -12.0,
        10.0,
        levels_required=5,
        max_cool_c_per_min=0.25,
        max_heat_c_per_min=0.3,
    )
    limits = Limits(duration_max_min=240.0)
    box = dict(tau_s=(2300.0, 2500.0), dt0_c=(2.5, 3.5))
    said: list[str] = []
    search, notes, fallback = search_robust(
        spec, ThermalParams(), limits, *box.values(), said.append, LpStats(), lambda _: False
    )
    assert any("held within" in m for m in said), said  # the default slack did not fit
    assert search.best is not None and fallback is None and notes == [], notes
    assert search.ctx.robust_slack_c_per_min < ROBUST_SLACK_C_PER_MIN
    u, _, _ = polish(search.ctx, search.best[0])
    programme = operator_programme(u, spec, limits)
    cov = _box_coverage(programme, tmp_path, (-2.0, 0.0), 5, *box.values())
    assert cov.min() == 1.0


def test_the_box_check_holds_only_where_the_device_stays_within_its_limits(tmp_path):
    """A table that takes the low-dT0 device past its limit was said to hold there ("it
    holds for dT0 1..3.89 °C" with the device at -52.92 °C at dT0 1; red team), and a
    nominal-point plan's note named a corner of the box without the point it was made
    for. The box check's points hold only where the device stays within its limits
    too, and the part named holds the nominal point where one can: checked against
    scipy's integration of the table at every grid point."""
    spec = ExperimentSpec("L", -2.0, 0.0, -12.0, 10.0, levels_required=2)
    params = ThermalParams()
    plan = plan_experiment(spec, params, Limits(duration_max_min=120.0))
    box = ((1800.0, 3000.0), (0.0, 6.0))
    taus, dt0s = np.meshgrid(np.linspace(*box[0], 25), np.linspace(*box[1], 19), indexing="ij")
    knots_t, knots_tk = chamber_knots(plan.programme.to_csv(tmp_path / "s.csv"))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, taus.ravel(), dt0s.ravel())
    # a device limit between the box's coldest and the nominal device's coldest point
    t_min = temp.min(axis=1).reshape(taus.shape)
    floor_c = 0.5 * (t_min.min() + t_min[12, 9])
    limits = dataclasses.replace(plan.limits, device_min_c=floor_c)
    check = verify_robust(plan.programme, spec, params, *box, limits)
    cov = np.array(
        [
            np.mean(levels_per_bin(t, g, -2.0, 0.0, 0.05) >= 2)
            for t, g in zip(temp, grad, strict=True)
        ]
    ).reshape(taus.shape)
    within = t_min >= floor_c
    assert not within.all() and within[12, 9]
    assert not check["holds"] and not check["device_held"]
    part = check["covered_box"]
    assert part is not None
    inside = (
        (taus >= part["tau_s_range"][0])
        & (taus <= part["tau_s_range"][1])
        & (dt0s >= part["dt0_c_range"][0])
        & (dt0s <= part["dt0_c_range"][1])
    )
    assert inside.sum() == part["n_points"]
    assert (cov[inside] >= 1.0).all() and within[inside].all()  # every point named holds
    assert inside[12, 9]  # around the nominal point (tau 2400 s, dT0 3 degC)
    assert "the device passes its limits" in box_note(check)
    # a narrow box the table covers everywhere does not hold where the device goes past
    narrow = ((2300.0, 2500.0), (2.5, 3.5))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, [2300.0, 2500.0], [2.5, 2.5])
    assert all(
        (levels_per_bin(t, g, -2.0, 0.0, 0.05) >= 2).all() for t, g in zip(temp, grad, strict=True)
    )
    limits = dataclasses.replace(plan.limits, device_min_c=float(temp.min()) + 0.05)
    check = verify_robust(plan.programme, spec, params, *narrow, limits)
    assert check["worst"]["coverage"] == 1.0 and not check["holds"]
    assert box_note(check).startswith("coverage holds everywhere in the robust box, but")


def test_too_short_a_request_names_the_requirement():
    # SMALL narrowed to [-2, 0] degC at 2 levels in 30 min: the same error from the same
    # place, after a search a third as long as SMALL's within 40 min
    spec = ExperimentSpec(**dict(SMALL, working_lo_c=-2.0, approx_lo_c=-12.0, levels_required=2))
    with pytest.raises(InfeasiblePlanError, match="best reachable coverage") as info:
        plan_experiment(spec, limits=Limits(duration_max_min=30.0), require_complete=True)
    assert info.value.best_coverage is not None and info.value.best_coverage < 1.0


def test_a_bin_the_chamber_cannot_reach_is_named_in_the_error_with_the_floor_it_needs():
    # floor -1.5 + dT0 3 = 1.5 degC: the device never enters [0, 1) degC, for any budget
    spec = ExperimentSpec("unreachable", 0.0, 4.0, -2.0, 6.0, levels_required=3)
    limits = Limits(chamber_min_c=-1.5, duration_max_min=200.0)
    with pytest.raises(InfeasiblePlanError) as info:
        plan_experiment(spec, ThermalParams(dt0_c=3.0), limits, effort_s=5.0)
    msg = str(info.value)
    assert "some bin cannot be crossed at all" in msg and "inf min" not in msg
    assert "not searched" not in msg  # the levels were searched (for a partial plan)
    # the binding limit and the floor it needs: past lo - edge margin - dT0 = -3.25 degC
    assert "cannot bring the device below 1.5 °C" in msg
    assert "a floor below -3.25 °C is needed" in msg
    assert "\n" not in msg  # one line for the CLI
    # the cause leads (it came after what the search saw), and no advice that cannot help
    assert msg.startswith("unreachable: no complete plan exists") and "The search:" in msg
    assert "Lengthen the duration" not in msg


def test_the_part_of_the_region_the_chamber_can_reach_is_planned(tmp_path):
    """The same floor with a fast device (tau 600 s) and [0, 6] degC: the bins below
    1.5 degC (floor + dT0) cannot be reached, but [3, 6] can, with room for a cooling band
    above the floor. The answer is a plan of that part (it was an error; 5 levels do not
    fit in 90 min, so the part is graded), with the floor the whole region needs; the
    part's levels re-counted from an independent ODE solution."""
    spec = ExperimentSpec("reach", 0.0, 6.0, -2.0, 8.0, levels_required=5)
    params = ThermalParams(tau_s=600.0, dt0_c=3.0)
    limits = Limits(chamber_min_c=-1.5, duration_max_min=90.0)
    plan = plan_experiment(spec, params, limits, effort_s=5.0)
    assert not plan.complete and math.isinf(plan.duration_lower_bound_min)
    k = plan.levels_planned
    assert k is not None and 2 <= k < 5
    (note,) = [n for n in plan.notes if n.startswith("PARTIAL")]
    assert any("a floor below -3.25 °C is needed" in n for n in plan.notes), plan.notes
    # the part's own graded note counts the part's bins and says so (it read as the
    # region's: 'weakest bin 4' beside a region whose weakest bin had 0)
    assert not any(n.startswith("GRADED") for n in plan.notes)
    assert any(n.startswith("in the part planned, [3, 6] °C: GRADED:") for n in plan.notes)
    res = table_check(
        plan.programme.to_csv(tmp_path / "steps.csv"), (0.0, 6.0), 5, tau_s=600.0, dt0_c=3.0
    )
    part = res["levels"][3:]  # [3, 4), [4, 5), [5, 6)
    assert (part >= k).all()
    assert f"[3, 6] °C, with {k} levels in {np.mean(part >= k):.0%} of its bins" in note
    assert (res["levels"][:2] == 0).all()  # below floor + dT0 = 1.5 degC: never entered
    assert list(res["levels"]) == list(plan.coverage.levels)
    assert res["duration_min"] <= 90.0 + 1e-9 and res["device_min_c"] > 1.5
    assert abs(res["chamber_end_c"] - limits.end_c) <= limits.end_tol_c
    assert res["rates_c_per_min"].min() >= limits.rate_min_c_per_min - 1e-3


def test_shortfall_names_the_binding_chamber_limit():
    w1 = ExperimentSpec("W1", -50, -30, -52, -20)
    notes = explain_shortfall(w1, ThermalParams(), Limits(chamber_min_c=-52.0))
    assert any("cannot bring the device below -49" in n for n in notes)
    # the ceiling's side: reaching the region needs a ceiling past hi + edge margin - dT0
    # = 57.25 degC, and the proven duration bound fits 540 min only past 61.25 degC (the
    # last value it rules out, to the bisection's 0.25 degC; 61.47 fits)
    w4 = ExperimentSpec("W4", 30, 60, 20, 62)
    notes = explain_shortfall(w4, ThermalParams(), Limits(chamber_max_c=55.0))
    assert any(
        "cannot bring the device above 58" in n and "a ceiling above 61.25 °C is needed" in n
        for n in notes
    ), notes
    notes = explain_shortfall(w1, ThermalParams(), Limits(chamber_min_c=-60.0))
    assert any("0.175" in n for n in notes)  # (Tk_min + dT0 - T)/tau at -50 degC
    assert explain_shortfall(w1, ThermalParams(), Limits()) == []


@pytest.mark.parametrize(
    "changes, name",
    [
        ({"levels_required": 1}, "levels_required"),
        ({"segment_min": 2.5}, "segment_min"),
        ({"objective": "fastest"}, "objective"),
        ({"approx_lo_c": -5.0}, "approximation region"),
        ({"working_hi_c": -10.5}, "lo_c < hi_c"),
    ],
)
def test_bad_specs_are_refused_by_name(changes, name):
    with pytest.raises(ParameterError, match=name):
        ExperimentSpec(**{**SMALL, **changes})


def test_robust_scenarios_cover_the_box_ends():
    from schedsyn.planner import robust_scenarios

    sc = robust_scenarios(ThermalParams(), (2000.0, 2800.0), (0.0, 6.0))
    taus = sorted({p.tau_s for p in sc})
    dt0s = sorted({p.dt0_c for p in sc})
    assert taus[0] == 2000.0 and taus[-1] == 2800.0 and len(taus) == 3
    assert dt0s == [0.0, 6.0]  # T and g are affine in dT0: the two ends suffice
    assert robust_scenarios(ThermalParams(), None, None) == [ThermalParams()]
    with pytest.raises(ParameterError, match="tau_s"):
        robust_scenarios(ThermalParams(), (2800.0, 2000.0), None)


def test_temperature_is_affine_in_dt0_so_box_ends_bound_it():
    """The fact the robust formulation rests on: for fixed rates, T(dT0) is affine."""
    prog = Programme([60.0, 90.0, 120.0], [-0.8, 0.5, 0.0])
    t = [simulate(prog, ThermalParams(dt0_c=d), dt_min=1.0).t_c for d in (0.0, 2.0, 6.0)]
    np.testing.assert_allclose(t[1], t[0] + (t[2] - t[0]) * (2.0 / 6.0), atol=1e-9)


def test_check_tables_script_agrees_with_the_plan(small_plan, tmp_path):
    """scripts/check_tables.py (separate code: scipy ODE, its own counting) on the exported
    table reproduces the plan's coverage and limits."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "check_tables.py"
    spec_ = importlib.util.spec_from_file_location("check_tables", path)
    mod = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(mod)
    plan = small_plan
    steps = plan.programme.to_csv(tmp_path / "steps.csv")
    res = mod.check(
        steps,
        plan.params.tau_s,
        plan.params.dt0_c,
        plan.spec.working_lo_c,
        plan.spec.working_hi_c,
        plan.spec.levels_required,
        plan.spec.delta_c_per_min,
    )
    assert res["coverage"] == pytest.approx(plan.coverage.coverage)
    assert res["min_levels"] == plan.coverage.min_levels
    assert res["chamber_start_c"] == 20.0 and abs(res["chamber_end_c"] - 20.0) <= 0.5
    assert SMALL_LIMITS.rate_min_c_per_min - 1e-9 <= res["rate_min"]
    assert res["rate_max"] <= SMALL_LIMITS.rate_max_c_per_min + 1e-9
    # a table that stops half-way is caught: its coverage drops
    half = plan.programme.to_frame().iloc[: plan.steps // 2]
    half.to_csv(tmp_path / "half.csv", index=False)
    cut = mod.check(
        tmp_path / "half.csv",
        plan.params.tau_s,
        plan.params.dt0_c,
        plan.spec.working_lo_c,
        plan.spec.working_hi_c,
        plan.spec.levels_required,
        plan.spec.delta_c_per_min,
    )
    assert cut["coverage"] < res["coverage"]


def test_narrow_mid_range_region_with_six_levels_plans_completely(tmp_path):
    """Fast sweeps across short band pieces: planned knot times must not drift (this
    region could not be planned at all when each piece was rounded on its own)."""
    spec = ExperimentSpec("mid", -5.0, 5.0, -15.0, 15.0)
    plan = plan_experiment(spec)
    assert plan.complete, plan.notes
    prog = read_steps(plan.programme.to_csv(tmp_path / "mid.csv"), Limits())
    _, temp, grad = _ode_trajectory(prog, plan.params)
    rep = coverage_report(temp, grad, BinGrid(-5.0, 5.0), 6)
    assert rep.complete and prog.total_min <= 540.0


def _small_probe():
    """A feasible probe LP on the small spec and its LP statistics."""
    from schedsyn.model import FirstOrderLag
    from schedsyn.planner import Scenario
    from schedsyn.planner.lp import Context, LpStats, Responses, SubLP

    spec = ExperimentSpec(**SMALL)
    p = ThermalParams()
    stats = LpStats()
    resp = Responses([Scenario(p, FirstOrderLag(p))], 24, 5.0, SMALL_LIMITS)
    lp = SubLP(Context(spec, SMALL_LIMITS, resp, stats), np.zeros(0), 24)
    lp.chamber()
    lp.device()
    lp.chamber_end(20.0)
    lp.le(lp.scen[0][0][60], -5.0 - lp.scen[0][1][60])  # reach -5 degC at 60 min
    return lp, stats


class _FailedClarabel:
    """Stands in for clarabel.DefaultSolver: gives up as on a numerical failure."""

    def __init__(self, *args):
        pass

    def solve(self):
        return type("Solution", (), {"status": "NumericalError", "x": []})()


def test_a_solver_failure_falls_back_to_highs_and_is_never_counted_as_infeasible(monkeypatch):
    import clarabel
    from scipy import optimize

    from schedsyn.errors import SolverFailedError
    from schedsyn.planner.lp import require_solvable

    lp, stats = _small_probe()
    reference = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
    assert reference is not None and stats.optimal == 1
    monkeypatch.setattr(clarabel, "DefaultSolver", _FailedClarabel)
    # HiGHS solves the same LP: the same optimum (the L1 norm of the rates)
    x = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
    assert x is not None and stats.fallbacks == 1
    assert np.abs(x).sum() == pytest.approx(np.abs(reference).sum(), rel=1e-6)
    # both fail: a failure, not infeasibility -- and it says so when nothing else is known
    failed = type("Result", (), {"status": 4, "message": "numerical difficulties", "x": None})
    monkeypatch.setattr(optimize, "linprog", lambda *a, **k: failed())
    assert lp.solve_direct(np.zeros(lp.n)) is None
    assert (stats.failed, stats.infeasible) == (1, 0)
    with pytest.raises(SolverFailedError, match="not evidence that the request is impossible"):
        require_solvable(stats, "S")


def test_plan_experiment_raises_solver_failed_when_the_solvers_fail(monkeypatch):
    import clarabel
    from scipy import optimize

    from schedsyn.errors import SolverFailedError

    failed = type("Result", (), {"status": 4, "message": "numerical difficulties", "x": None})
    monkeypatch.setattr(clarabel, "DefaultSolver", _FailedClarabel)
    monkeypatch.setattr(optimize, "linprog", lambda *a, **k: failed())
    # SMALL narrowed to [-2, 0] degC at 2 levels: every LP of its search fails (and no
    # fewer count is left for a graded search: with 3 levels its failures added two thirds
    # of the time and were swallowed as "that count is skipped", so they decided nothing)
    spec = ExperimentSpec(**dict(SMALL, working_lo_c=-2.0, approx_lo_c=-12.0, levels_required=2))
    with pytest.raises(SolverFailedError) as info:
        plan_experiment(spec, ThermalParams(), SMALL_LIMITS)
    assert not isinstance(info.value, InfeasiblePlanError)


def test_a_region_beyond_the_device_limits_is_refused_before_any_lp(monkeypatch):
    from schedsyn.planner import core

    def no_search(*args, **kwargs):
        raise AssertionError("the planner searched a request it should have refused")

    monkeypatch.setattr(core, "synthesise", no_search)
    spec = ExperimentSpec("hot", 40.0, 62.0, 30.0, 62.0)  # the top edge + 0.5 > device 62
    with pytest.raises(ParameterError, match="outside its limits -52 .. 62"):
        plan_experiment(spec, ThermalParams(), Limits())


#: How far the test programmes pass a device limit: less than 1 degC on purpose.
GRAZE_C = 0.5


def _hot_and_cold_programmes():
    """Heat to 55 degC and hold (the device creeps towards 58 degC), back to 20; and cool
    to -40 degC and hold (the device sinks towards -37 degC), back to 20."""
    hot = Programme([35.0, 100.0, 35.0, 30.0], [1.0, 0.0, -1.0, 0.0])
    cold = Programme([60.0, 110.0, 20.0, 30.0], [-1.0, 0.0, 3.0, 0.0])
    return {"max": hot, "min": cold}


@pytest.mark.parametrize("robust", [False, True], ids=["nominal", "two-scenarios"])
@pytest.mark.parametrize("side", ["max", "min"])
def test_check_programme_catches_a_device_limit_grazed_by_half_a_degree(side, robust, tmp_path):
    """The device's extreme comes from scipy's integration of the table as typed; a limit
    0.5 degC inside it is reported, a limit 0.01 degC outside it is not."""
    prog = _hot_and_cold_programmes()[side]
    scenarios = (
        [ThermalParams(tau_s=2000.0, dt0_c=2.0), ThermalParams(tau_s=2800.0, dt0_c=4.0)]
        if robust
        else [ThermalParams()]
    )
    knots_t, knots_tk = chamber_knots(prog.to_csv(tmp_path / f"{side}.csv"))
    _, temp, _ = ode_trajectories(
        knots_t, knots_tk, [p.tau_s for p in scenarios], [p.dt0_c for p in scenarios]
    )
    extreme = temp.max() if side == "max" else temp.min()
    spec = ExperimentSpec("G", 0.0, 10.0, -5.0, 15.0)
    sign = 1.0 if side == "max" else -1.0

    def limits(device_c):
        return Limits(**{f"device_{side}_c": device_c})

    *_, problems, t_lo, t_hi = check_programme(
        prog, spec, limits(extreme - sign * GRAZE_C), scenarios
    )
    assert (t_hi if side == "max" else t_lo) == pytest.approx(extreme, abs=1e-3)
    device = [s for s in problems if "device reaches" in s]
    assert len(device) == 1, problems
    assert f"{extreme - sign * GRAZE_C:g}" in device[0]
    assert (" design scenarios " in device[0]) == robust
    *_, problems, _, _ = check_programme(prog, spec, limits(extreme + sign * 0.01), scenarios)
    assert problems == []


def test_a_robust_plan_reports_the_nominal_point_and_the_box_by_name(small_robust_plan):
    """Coverage at the nominal point, the worst design scenario and the box check, each
    named in plan.json; the nominal coverage is that of an independent re-simulation at
    the nominal (tau, dT0), and no fallback was needed for this box."""
    plan = small_robust_plan
    doc = plan.to_json_dict()
    traj = simulate(plan.programme, plan.params, dt_min=0.1, t0_c=ROBUST_LIMITS.t_init_c)
    rep = coverage_report(traj.t_c, traj.g_c_per_min, plan.spec.grid, plan.spec.levels_required)
    assert doc["coverage_nominal"] == rep.coverage and doc["min_levels_nominal"] == rep.min_levels
    assert doc["coverage_worst_design_scenario"] == plan.coverage.coverage
    assert doc["robust_fallback"] is None and not any("FALLBACK" in n for n in plan.notes)


def test_the_step_table_carries_the_plan_and_simulates_with_its_model(tmp_path):
    """Plan.programme carries region, model and limits: simulate(plan.programme) with no
    parameters uses the plan's tau and dT0 (here not the defaults), and so does the
    written table read back."""
    params = ThermalParams(tau_s=1500.0, dt0_c=1.0)
    plan = plan_experiment(ExperimentSpec(**SMALL), params, SMALL_LIMITS)
    meta = plan.programme.meta
    assert (meta.working_lo_c, meta.working_hi_c) == (SMALL["working_lo_c"], SMALL["working_hi_c"])
    assert (meta.tau_s, meta.dt0_c) == (1500.0, 1.0)
    for prog in (plan.programme, read_steps(plan.programme.to_csv(tmp_path / "s.csv"))):
        traj = simulate(prog)
        rep = coverage_report(traj.t_c, traj.g_c_per_min, plan.spec.grid, 3)
        assert rep.coverage == plan.coverage.coverage and plan.complete


def test_require_complete_never_returns_a_graded_plan():
    """85 min fit 2 levels per bin of [-2, 0] degC but not 3 (bound 92 min): graded, a
    plan with 2 levels comes back; asked for a complete plan, the planner refuses instead.
    ([-4, 0] degC in 100 min, and SMALL in 110 min, are the same case with longer
    searches.)"""
    spec = ExperimentSpec(**dict(SMALL, working_lo_c=-2.0, approx_lo_c=-12.0))
    limits = Limits(duration_max_min=85.0)
    graded = plan_experiment(spec, limits=limits)
    assert not graded.complete and graded.levels_planned == 2
    with pytest.raises(InfeasiblePlanError, match="no complete plan was found|no programme"):
        plan_experiment(spec, limits=limits, require_complete=True)


def test_the_plan_that_fell_short_survives_a_process_boundary_with_its_error(small_plan):
    """A worker's InfeasiblePlanError carries the plan it made (``best_plan``: the graded
    search keeps a sub-region plan of fewer levels from it) to the parent process."""
    err = InfeasiblePlanError("short", best_coverage=0.5, best_plan=small_plan)
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == "short" and again.best_coverage == 0.5
    assert again.best_plan.duration_min == small_plan.duration_min
    assert np.array_equal(
        again.best_plan.programme.rates_c_per_min, small_plan.programme.rates_c_per_min
    )


def test_an_over_long_plan_that_cannot_be_cut_leaves_the_other_fallbacks(monkeypatch):
    """[-2, 0] degC in 85 min: the 3-level sweeps overrun and the planner falls back. When
    the over-long programme cannot be cut to end in time (forced here), that one option is
    dropped and the graded plan still comes back; it used to abort the whole plan with a
    solver error. (SMALL in 110 min is the same case, with a search four times as long.)
    """
    from schedsyn.planner import core

    calls = []

    def no_cut(*args, **kwargs):
        calls.append(args)
        return None

    monkeypatch.setattr(core, "truncate", no_cut)
    spec = ExperimentSpec(**dict(SMALL, working_lo_c=-2.0, approx_lo_c=-12.0))
    plan = plan_experiment(spec, limits=Limits(duration_max_min=85.0))
    assert calls, "the over-long option was never tried: the test exercises nothing"
    assert not plan.complete and plan.levels_planned == 2


def test_quiet_stdout_fd_silences_c_level_output(capfd):
    """HiGHS prints its banner from C++ (file descriptor 1) whatever its options: the
    planner wraps its calls so that nothing reaches the user's terminal."""
    import os

    from schedsyn.planner.lp import quiet_stdout_fd

    os.write(1, b"before\n")
    with quiet_stdout_fd():
        os.write(1, b"banner from C\n")
    os.write(1, b"after\n")
    assert capfd.readouterr().out == "before\nafter\n"


def test_a_level_pair_right_at_delta_is_counted_as_a_finer_sampling_counts_it():
    """A table whose two levels in bin [-49, -48) are 0.0504 apart sampled every 0.1 min
    but 0.0500 (short of delta) sampled every 0.05 or 0.01 min: the planner's check keeps
    the worse count, so its claim agrees with an independent count at fine sampling."""
    from pathlib import Path

    from schedsyn.programme import read_steps

    steps = Path(__file__).parent / "data" / "plans" / "w1_slow_chamber_720_steps.csv"
    prog = read_steps(steps)
    spec = ExperimentSpec("W1", -50.0, -30.0, -52.0, -20.0)
    limits = Limits(rate_min_c_per_min=-0.5, rate_max_c_per_min=1.5, duration_max_min=720.0)
    rep, *_ = check_programme(prog, spec, limits, [ThermalParams()])
    knots_t, knots_tk = chamber_knots(steps)
    counts = {}
    for dt_min in (0.1, 0.05, 0.01):
        _, temp, grad = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=dt_min)
        counts[dt_min] = levels_per_bin(temp[0], grad[0], -50.0, -30.0, 0.05)
    assert counts[0.1][1] == 6 and counts[0.05][1] == counts[0.01][1] == 5  # the case holds
    np.testing.assert_array_equal(rep.levels, counts[0.01])
    assert not rep.complete and rep.coverage == pytest.approx(0.9)


def test_the_finer_sampling_runs_only_where_the_count_is_close_to_changing(monkeypatch):
    """The 0.02-min simulation (8x the cost) runs for the table with levels right at delta
    apart and not for W2's table, whose levels are clear of it."""
    from pathlib import Path

    import schedsyn.planner.check as check_mod
    from schedsyn.programme import read_steps

    seen = []
    real = check_mod.simulate

    def counting(*args, **kwargs):
        seen.append(kwargs["dt_min"])
        return real(*args, **kwargs)

    monkeypatch.setattr(check_mod, "simulate", counting)
    data = Path(__file__).parent / "data" / "plans"
    slow = Limits(rate_min_c_per_min=-0.5, rate_max_c_per_min=1.5, duration_max_min=720.0)
    for name, spec, limits, fine in (
        ("w2_steps.csv", ExperimentSpec("W2", -30.0, 0.0, -40.0, 10.0), Limits(), False),
        (
            "w1_slow_chamber_720_steps.csv",
            ExperimentSpec("W1", -50.0, -30.0, -52.0, -20.0),
            slow,
            True,
        ),
    ):
        seen.clear()
        check_programme(read_steps(data / name), spec, limits, [ThermalParams()])
        assert seen == ([0.1, 0.02] if fine else [0.1]), name


def test_the_report_says_no_complete_plan_exists_when_the_bound_is_infinite(small_plan):
    from schedsyn.cli.plan import report_plan

    finite = [line for line in report_plan(small_plan) if "proven" in line]
    assert len(finite) == 1 and "min (this plan +" in finite[0]
    proven_none = dataclasses.replace(small_plan, duration_lower_bound_min=math.inf)
    (line,) = [line for line in report_plan(proven_none) if "proven" in line]
    assert "no complete plan exists" in line and "inf" not in line


def _strict_load(path):
    """json.loads that refuses NaN and Infinity, as strict parsers (JavaScript, jq) do."""
    import json

    def refuse(name):
        raise ValueError(f"{path.name} holds {name}, which is not JSON")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def test_plan_json_is_strict_json_and_says_when_no_complete_plan_exists(small_plan, tmp_path):
    from schedsyn.cli.plan import write_plan_outputs

    write_plan_outputs(small_plan, tmp_path / "finite")
    doc = _strict_load(tmp_path / "finite" / "plan.json")
    assert doc["duration_lower_bound_min"] == pytest.approx(small_plan.duration_lower_bound_min)
    assert doc["complete_plan_proven_impossible"] is False
    # a bound past the budget, and an infinite one (some bin cannot be crossed at all)
    over = small_plan.limits.duration_max_min + 1.0
    for bound, written in ((over, over), (math.inf, None)):
        proven = dataclasses.replace(small_plan, duration_lower_bound_min=bound)
        write_plan_outputs(proven, tmp_path / str(bound))
        doc = _strict_load(tmp_path / str(bound) / "plan.json")
        assert doc["duration_lower_bound_min"] == written
        assert doc["complete_plan_proven_impossible"] is True


def test_a_binding_ceiling_is_explained_with_what_the_levels_need():
    """Red team: "3 heating levels need clearly more" than 0.227 degC/min, although three
    levels 0.05 apart need only about 0.15; the note now gives both figures and where
    planning gets hard (HEADROOM_C_PER_MIN above the levels' spread). g at the ceiling:
    (80 - 2.4 - 58) / (5180 / 60) = 0.227 degC/min."""
    from schedsyn.planner.explain import explain_shortfall

    spec = ExperimentSpec("x", 46.0, 58.0, 36.0, 62.0)
    notes = explain_shortfall(spec, ThermalParams(tau_s=5180.0, dt0_c=-2.4), Limits())
    (note,) = [n for n in notes if "chamber ceiling" in n]
    assert "at most 0.227 °C/min" in note and "at least about 0.15 °C/min" in note, note
    assert "hard below 0.25 °C/min" in note and "raise the ceiling or lower the level" in note


def test_the_solve_time_of_an_incomplete_plan_counts_the_timetable_stage(monkeypatch):
    """An incomplete plan goes to the timetable stage, which may find nothing after
    minutes; the plan said "solved in 49 s" after 315 s (red team). Both stages stubbed:
    the stage takes 0.3 s and finds nothing, and the returned plan's time includes it."""
    import dataclasses
    import time

    from schedsyn.planner import core

    @dataclasses.dataclass
    class Stub:
        complete: bool = False
        solve_s: float = 0.0

    monkeypatch.setattr(core, "_plan", lambda *a, **k: Stub())
    monkeypatch.setattr(core, "_timetable_plan", lambda *a, **k: time.sleep(0.3))
    plan = plan_experiment(ExperimentSpec(**SMALL), limits=Limits(duration_max_min=60.0))
    assert isinstance(plan, Stub) and plan.solve_s >= 0.3
