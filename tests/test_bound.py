"""The proven lower bound on a plan's duration (schedsyn.planner.bound)."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from schedsyn import Limits, ThermalParams, simulate
from schedsyn.planner import ExperimentSpec, duration_lower_bound, plan_experiment
from schedsyn.planner.bound import _Curves, _sides, approach_minutes
from schedsyn.planner.physics import accel_time, stop_distance, stop_time

TAU_MIN = 40.0


def _speed_ode(rate, u0, distance, tau=TAU_MIN):
    """Speed along a full-rate curve by scipy: dv/dx = (rate - v)/(tau v), dt/dx = 1/v."""
    sol = solve_ivp(
        lambda x, y: [(rate - y[0]) / (tau * y[0]), 1.0 / y[0]],
        (0.0, distance),
        [u0, 0.0],
        rtol=1e-10,
        atol=1e-12,
        max_step=0.01,
    )
    return sol.y[0, -1], sol.y[1, -1]


@pytest.mark.parametrize("rate", [1.0, 3.0])
@pytest.mark.parametrize("u0", [0.05, 0.3, 0.8])
def test_the_tabulated_full_rate_curves_match_scipy(rate, u0):
    """Speeding up and braking across one 1 degC bin: end speed and bin mean (1 / time)."""
    if u0 >= rate:
        pytest.skip("a speed-up starts below the rate")
    side = _sides(ThermalParams(), Limits())[+1 if rate == 3.0 else -1]
    curves = _Curves(side, 1.0, TAU_MIN, side.r_fwd + 0.1)
    i = int(np.searchsorted(curves.u, u0))
    u = curves.u[i]
    v_end, t = _speed_ode(side.r_fwd, u, 1.0)
    assert curves.a_end[i] == pytest.approx(v_end, rel=1e-6)
    assert curves.a_mean[i] == pytest.approx(1.0 / t, rel=1e-5)
    # braking at the other rate, dv/dx = -(r' + v)/(tau v), where it crosses the whole bin
    if stop_distance(u, side.r_back, TAU_MIN) > 1.05:
        v_end, t = _speed_ode(-side.r_back, u, 1.0)
        assert curves.b_end[i] == pytest.approx(v_end, rel=1e-5)
        assert curves.b_mean[i] == pytest.approx(1.0 / t, rel=1e-5)
    else:  # it stops inside the bin: it never leaves it
        assert curves.b_end[i] == 0.0 and curves.b_mean[i] == 0.0


def test_turning_times_and_the_approach_match_the_ode():
    """accel_time, stop_time and approach_minutes against the lag integrated by scipy."""
    tau, rate = TAU_MIN, 3.0
    # g' = (U - g)/tau from rest: time to reach 1.2 degC/min
    sol = solve_ivp(
        lambda t, y: [(rate - y[0]) / tau],
        (0, 100),
        [0.0],
        events=lambda t, y: y[0] - 1.2,
        rtol=1e-10,
        atol=1e-12,
    )
    assert accel_time(1.2, rate, tau) == pytest.approx(sol.t_events[0][0], rel=1e-6)
    sol = solve_ivp(
        lambda t, y: [(-1.0 - y[0]) / tau],
        (0, 100),
        [0.8],
        events=lambda t, y: y[0],
        rtol=1e-10,
        atol=1e-12,
    )
    assert stop_time(0.8, 1.0, tau) == pytest.approx(sol.t_events[0][0], rel=1e-6)
    # from 20 degC with g0 = 0.075 degC/min, cooling at 1 degC/min: first time at 0 degC
    sol = solve_ivp(
        lambda t, y: [y[1], (-1.0 - y[1]) / tau],
        (0, 500),
        [20.0, 0.075],
        events=lambda t, y: y[0],
        rtol=1e-10,
        atol=1e-12,
    )
    assert approach_minutes(20.0, 0.075, 0.0, 1.0, tau) == pytest.approx(
        sol.t_events[0][0], rel=1e-6
    )


REQUESTS = st.fixed_dictionaries(
    {
        "lo": st.integers(-40, 45),
        "width": st.integers(3, 8),
        "levels": st.integers(2, 4),
        "delta": st.sampled_from([0.05, 0.08]),
        "tau_s": st.sampled_from([1200.0, 2400.0, 3000.0]),
        "dt0_c": st.sampled_from([0.0, 3.0, 5.0]),
        "cool": st.sampled_from([0.7, 1.0, 2.0]),
        "heat": st.sampled_from([1.5, 3.0]),
    }
)


@settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(REQUESTS)
def test_no_complete_plan_is_shorter_than_its_bound(req):
    """The bound is valid: every complete plan schedsyn finds lasts at least as long (the
    plan's duration comes from its exported table; its completeness from re-simulation).
    Checked with the levels' dual on, the tightest variant."""
    spec = ExperimentSpec(
        "P",
        req["lo"],
        req["lo"] + req["width"],
        req["lo"] - 5,
        req["lo"] + req["width"] + 5,
        levels_required=req["levels"],
        delta_c_per_min=req["delta"],
    )
    params = ThermalParams(tau_s=req["tau_s"], dt0_c=req["dt0_c"])
    limits = Limits(
        rate_min_c_per_min=-req["cool"],
        rate_max_c_per_min=req["heat"],
        duration_max_min=480.0,
    )
    reported = duration_lower_bound(spec, params, limits).lower_bound_min
    bound = duration_lower_bound(spec, params, limits, tighten=True).lower_bound_min
    assert bound >= reported - 1e-9  # the levels' dual only raises it
    plan = plan_experiment(spec, params, limits)
    assert plan.duration_lower_bound_min == pytest.approx(reported)
    if plan.complete:
        traj = simulate(plan.programme, params, dt_min=0.1, t0_c=limits.t_init_c)
        assert traj.duration_min == pytest.approx(plan.duration_min)
        assert plan.duration_min >= bound, (plan.duration_min, bound)
    else:  # an incomplete plan proves nothing about the bound, but the bound is finite
        assert math.isfinite(bound) or not plan.complete


def test_the_bound_grows_with_what_is_asked_and_shrinks_with_a_faster_chamber():
    spec = ExperimentSpec("M", -30.0, -10.0, -40.0, 0.0)
    base = duration_lower_bound(spec).lower_bound_min
    more_levels = duration_lower_bound(
        ExperimentSpec("M", -30.0, -10.0, -40.0, 0.0, levels_required=8)
    ).lower_bound_min
    wider = duration_lower_bound(ExperimentSpec("M", -35.0, -5.0, -45.0, 5.0)).lower_bound_min
    faster = duration_lower_bound(
        spec, limits=Limits(rate_min_c_per_min=-3.0, rate_max_c_per_min=3.0)
    ).lower_bound_min
    assert more_levels > base and wider > base and faster < base
    assert 0 < base < 540


def test_an_unreachable_bin_makes_the_bound_infinite():
    """A chamber floor that cannot bring the device to the region's bottom: no sweep can
    cross it, so no plan is complete at any duration."""
    spec = ExperimentSpec("U", -50.0, -30.0, -52.0, -20.0)
    assert math.isinf(
        duration_lower_bound(spec, limits=Limits(chamber_min_c=-45.0)).lower_bound_min
    )


@pytest.mark.parametrize(("dt0_c", "infinite"), [(-2.1, True), (-2.0, True), (-1.9, False)])
def test_a_bin_the_device_cannot_finish_makes_the_bound_infinite(dt0_c, infinite):
    """Red team: dT0 -2.1 °C with the chamber at 60 °C stops the device at 57.9 °C, so the
    bin [57, 58) of a region up to 58 °C is never crossed; its bound was 726 min (the
    bin's lower part is reachable). At -2.0 the device only tends to 58 °C."""
    spec = ExperimentSpec("hot", 50.0, 58.0, 40.0, 62.0)
    bound = duration_lower_bound(
        spec, ThermalParams(2400.0, dt0_c), Limits(chamber_max_c=60.0, duration_max_min=800.0)
    ).lower_bound_min
    assert math.isinf(bound) == infinite, bound


def test_paper_regions_bounds_are_below_the_plans_known_for_them():
    """W1 has a 480-min complete plan (README); its bound must lie below, and W2's below
    W2's known 480-min plan (issue 12)."""
    w1 = duration_lower_bound(ExperimentSpec("W1", -50.0, -30.0, -52.0, -20.0))
    w2 = duration_lower_bound(ExperimentSpec("W2", -30.0, 0.0, -40.0, 10.0))
    assert w1.lower_bound_min < 480.0 and w2.lower_bound_min < 480.0
    assert w1.crossing_min > 0 and w1.turning_min > 0


def _bang_bang_two_levels(spec: ExperimentSpec, limits: Limits, params: ThermalParams):
    """Shortest two-level run (one pass each way) among bang-bang programmes, by brute
    force over 1-min switch times: full rate towards the region, full rate back through it,
    then the chamber back to its end temperature at full rate. Simulated exactly and
    scored by the coverage metric: an achievable duration, independent of the bound.
    The runs are simulated shortest first, so the first complete one is the shortest (the
    same minimum as trying every pair, with a sixth of the simulations)."""
    from schedsyn import BinGrid, coverage_report
    from schedsyn.programme import Programme

    a, b = -limits.rate_min_c_per_min, limits.rate_max_c_per_min
    below = spec.working_hi_c < limits.t_init_c  # region below the start: cool first
    first, back = (-a, b) if below else (b, -a)
    grid = BinGrid(spec.working_lo_c, spec.working_hi_c)
    runs = []
    for t1 in np.arange(5.0, 240.0, 1.0):
        for t2 in np.arange(1.0, 160.0, 1.0):
            tk = limits.start_c + first * t1 + back * t2
            home = -a if tk > limits.end_c else b
            t3 = abs(tk - limits.end_c) / abs(home)
            durations = [t1, t2] + ([t3] if t3 > 1e-9 else [])
            runs.append((sum(durations), durations, [first, back, home][: len(durations)]))
    runs.sort(key=lambda run: run[0])  # stable: ties keep the order of the loops
    for _, durations, rates in runs:
        prog = Programme(np.array(durations), np.array(rates))
        traj = simulate(prog, params, dt_min=0.1, t0_c=limits.t_init_c)
        if coverage_report(traj.t_c, traj.g_c_per_min, grid, 2, spec.delta_c_per_min).complete:
            return prog.total_min
    return math.inf


@pytest.mark.parametrize(
    "lo, hi",
    [(-10.0, -5.0), (-20.0, -14.0), (28.0, 33.0)],
    ids=["near-below", "far-below", "above"],
)
def test_two_level_bound_is_below_and_close_to_a_bang_bang_run(lo, hi):
    """Two levels: the optimal run is bang-bang, so a brute-force search over switch times
    gives a duration close to the optimum (three full-rate segments are not always exactly
    optimal). The bound must not exceed it (valid) and must be within 15 % of it (tight: a
    dropped turning or approach term shows)."""
    spec = ExperimentSpec("T", lo, hi, lo - 5, hi + 5, levels_required=2)
    limits, params = Limits(), ThermalParams()
    achieved = _bang_bang_two_levels(spec, limits, params)
    bound = duration_lower_bound(spec, params, limits).lower_bound_min
    assert bound <= achieved
    assert bound >= 0.85 * achieved, (bound, achieved)


def test_sweeps_that_repeat_a_level_are_weighed_so_a_slow_direction_is_not_proof():
    """W1 over a -55 °C floor: near -50 °C the chamber lets the device cool at most about
    0.05-0.075 °C/min, too slow for three cooling levels 0.05 °C/min apart. That alone is
    not proof of impossibility: a plan may cool more often than it has cooling levels
    (repeating one) so that heating gives the other levels. The bound weighs such plans:
    finite, reached with more sweeps than levels, and still above the 540-min budget."""
    spec = ExperimentSpec("F", -50.0, -30.0, -55.0, -20.0)
    limits = Limits(chamber_min_c=-55.0)
    bound = duration_lower_bound(spec, limits=limits)
    assert math.isfinite(bound.lower_bound_min)
    assert bound.sweeps > spec.levels_required
    assert bound.lower_bound_min > 540.0


def _joint_two_ranks(probs, delta, reach, first_role):
    """The coupled problem the levels' dual relaxes, solved exactly by brute force: two
    sweeps of one direction, the slower at least ``delta`` below the faster in every bin,
    each within its caps and moving at most ``reach`` grid steps from bin to bin, one of
    them (either) in the first sweep's role; a dynamic programme over both speeds."""
    generic = probs[False, False]
    v, n_bins, w = generic.v, generic.caps.size, generic.width_c
    apart = v[None, :] <= v[:, None] - delta + 1e-12  # [i0, i1]: rank 1 below rank 0
    crossing = w / v[:, None] + w / v[None, :]
    best = math.inf
    for holder in (0, 1) if first_role else (None,):
        e0, e1 = ((probs[True, False] if k == holder else generic).entry for k in range(2))

        def allowed(j):
            return apart & (v[:, None] <= generic.caps[j]) & (v[None, :] <= generic.caps[j])

        cost = np.where(allowed(0), e0[:, None] + e1[None, :] + crossing, np.inf)
        for j in range(1, n_bins):
            padded = np.pad(cost, reach, constant_values=np.inf)
            prev = np.full_like(cost, np.inf)
            for a in range(2 * reach + 1):  # every joint move of at most reach steps
                for b in range(2 * reach + 1):
                    prev = np.minimum(prev, padded[a : a + v.size, b : b + v.size])
            cost = np.where(allowed(j), prev + crossing, np.inf)
        total = cost + generic.exit[:, None] + generic.exit[None, :]
        best = min(best, float(total.min()))
    return best


@pytest.mark.parametrize("first_role", [False, True], ids=["generic", "one-first"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_levels_dual_lies_between_the_ranks_apart_and_the_coupled_optimum(seed, first_role):
    """The Lagrangian dual that keeps a direction's levels delta apart (bound._coupled),
    on small made-up problems (speed grid, caps, continuity, edge costs): never above the
    coupled optimum found by brute force over both sweeps' joint profiles (weak duality,
    so the bound stays valid), and never below the ranks solved apart (it only tightens)."""
    from schedsyn.planner.bound import _coupled, _RankProblem, _solve_rank

    rng = np.random.default_rng(seed)
    step, delta = 0.01, 0.1
    v = step * np.arange(1, 121)
    n_bins = 5
    reach = int(rng.integers(3, 8))
    idx = np.arange(v.size)
    src_lo, src_hi = np.maximum(idx - reach, 0), np.minimum(idx + reach, v.size - 1)
    # caps above where the ranks want to be (edge costs hold them back), so only the
    # coupling keeps them apart
    caps = np.round(rng.uniform(1.0, 1.2, n_bins) / step) * step
    entry = rng.uniform(4.0, 8.0) * v**2  # turning dearer the faster the edge
    exit_ = rng.uniform(4.0, 8.0) * v**2
    generic = _RankProblem(v, caps, 1.0, src_lo, src_hi, entry, exit_)
    probs = {(False, False): generic}
    if first_role:
        probs[True, False] = _RankProblem(v, caps, 1.0, src_lo, src_hi, entry + 5 * v, exit_)
    shifts = [0, 1]
    apart = sum(
        _solve_rank(_RankProblem(v, caps - s * delta, 1.0, src_lo, src_hi, entry, exit_))[0]
        for s in shifts
    )
    if first_role:
        apart = min(
            _solve_rank(probs[True, False])[0]
            + _solve_rank(_RankProblem(v, caps - delta, 1.0, src_lo, src_hi, entry, exit_))[0],
            _solve_rank(generic)[0]
            + _solve_rank(_RankProblem(v, caps - delta, 1.0, src_lo, src_hi, entry + 5 * v, exit_))[
                0
            ],
        )
    dual = _coupled(probs, [caps - s * delta for s in shifts], 0, delta, step, apart)
    joint = _joint_two_ranks(probs, delta, reach, first_role)
    assert apart - 1e-9 <= dual <= joint + 1e-9, (apart, dual, joint)
    assert dual > apart + 0.5 * (joint - apart), "the dual should close most of the gap"


def test_the_levels_dual_gives_out_the_roles_among_the_feasible_ones():
    """A role no rank can take (the first sweep's approach impossible) makes the shape
    impossible; a role pair one rank cannot hold alone (first and last at once) is given
    to two ranks instead, and the bound stays finite."""
    from schedsyn.planner.bound import _coupled, _RankProblem

    step, delta = 0.01, 0.1
    v = step * np.arange(1, 121)
    idx = np.arange(v.size)
    src_lo, src_hi = np.maximum(idx - 4, 0), np.minimum(idx + 4, v.size - 1)
    caps = np.full(4, 1.1)
    cost = 6.0 * v**2

    def prob(entry, exit_):
        return _RankProblem(v, caps, 1.0, src_lo, src_hi, entry, exit_)

    never = np.full(v.size, np.inf)
    caps_by_rank = [caps, caps - delta]
    impossible = {(False, False): prob(cost, cost), (True, False): prob(never, cost)}
    assert math.isinf(_coupled(impossible, caps_by_rank, 0, delta, step, 10.0))
    apart_only = {
        (False, False): prob(cost, cost),
        (True, False): prob(cost + 1.0, cost),
        (False, True): prob(cost, cost + 1.0),
        (True, True): prob(never, never),
    }
    value = _coupled(apart_only, caps_by_rank, 0, delta, step, 10.0)
    assert math.isfinite(value) and value > 2.0  # both roles' extra minute is paid


def test_a_request_asked_twice_is_bounded_once_and_its_profiles_cannot_be_changed():
    # a plan near its budget asks for the dual bound to decide and again to report it
    spec = ExperimentSpec("twice", 0.0, 8.0, -5.0, 13.0, levels_required=3)
    first = duration_lower_bound(spec, ThermalParams(), Limits(), tighten=True)
    assert duration_lower_bound(spec, ThermalParams(), Limits(), tighten=True) is first
    # another request (here: the bound without the dual) is its own entry
    assert duration_lower_bound(spec, ThermalParams(), Limits(), tighten=False) is not first
    profile = next(iter(first.profiles.values()))[0]
    with pytest.raises(ValueError, match="read-only"):
        profile[0] = 0.0


def test_the_chamber_limit_said_to_be_needed_is_one_the_bound_allows():
    """Red team: "a floor of at most -54.25 °C is needed" read as a fix, but the bound
    there was 624 min against the 540-min budget. The floor said is now the last one the
    proven bound rules out (to 0.25 °C), with the first that fits beside it. A second red
    team: "-44.25 needed" where -43.3 fits the bound and -44 plans: the reach had one
    degree too many (floor + dT0 must pass the edge and its margin, no more)."""
    import re

    from schedsyn.planner.explain import explain_shortfall

    spec = ExperimentSpec("r09", -50.0, -40.0, -52.0, -30.0)
    params, limits = ThermalParams(2400.0, 3.0), Limits(chamber_min_c=-45.0)
    (note,) = [n for n in explain_shortfall(spec, params, limits) if "floor below" in n]
    m = re.search(r"a floor below (-?[\d.]+) °C is needed .*; (-?[\d.]+) °C fits the bound", note)
    ruled_out, fits = float(m.group(1)), float(m.group(2))
    assert "necessary, not sufficient" in note

    def bound(f):
        return duration_lower_bound(spec, params, Limits(chamber_min_c=f)).lower_bound_min

    assert bound(fits) <= limits.duration_max_min < bound(ruled_out)
    assert 0 < ruled_out - fits <= 0.5  # the bisection's resolution, rounded outward
    assert ruled_out < -53.25  # past the bare reach (-50 - 0.25 - 3), where it was 624 min
    # the red team's request: reach -43.25, not -44.25; the bound fits at -43.3
    spec2 = ExperimentSpec("p02", -40.0, -36.0, -45.0, -30.0)
    (note,) = [
        n
        for n in explain_shortfall(spec2, params, Limits(chamber_min_c=-43.0))
        if "floor below" in n
    ]
    assert "a floor below -43.25 °C is needed" in note, note
