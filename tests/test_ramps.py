"""The robust search's ramp rung (schedsyn.planner.ramps): its exact sampler, pass
gradients and level separation against independent code, and its programmes for a box
the band search falls back on, re-checked by scipy's ODE solver over the whole box."""

import re
from pathlib import Path

import numpy as np
import pytest
from independent import box_table_check, ode_trajectories

from schedsyn.coverage import level_separation
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, plan_experiment
from schedsyn.planner.ramps import (
    NO_PROGRAMME_COVERS_BOX,
    _lag_samples,
    box_spread_proof,
    pass_gradients,
    ramp_search,
    separation,
)
from schedsyn.programme import read_step_meta

HAND = Path(__file__).resolve().parents[1] / "data" / "robust_hand"


def _plain_passes(temp, grad, lo_c, n_bins):
    """Mean gradient of every pass of every bin, by a plain loop (as levels_per_bin)."""
    out = [[] for _ in range(n_bins)]
    current, run, count = -1, 0.0, 0
    for t, g in zip(temp.tolist(), grad.tolist(), strict=True):
        k = int(np.floor(t - lo_c)) if lo_c <= t < lo_c + n_bins else -1
        if k != current:
            if current >= 0:
                out[current].append(run / count)
            current, run, count = k, 0.0, 0
        run, count = run + g, count + 1
    if current >= 0:
        out[current].append(run / count)
    return out


def test_exact_sampler_matches_scipy_ode_solver():
    """T and g of a ramp-and-hold programme for several (tau, dT0), against solve_ivp."""
    durations = np.array([25.0, 12.0, 30.0, 7.0, 41.0])
    rates = np.array([-1.0, 0.0, 2.5, 0.0, -0.35])
    knots_t = np.concatenate(([0.0], np.cumsum(durations)))
    knots_tk = 20.0 + np.concatenate(([0.0], np.cumsum(durations * rates)))
    taus = np.array([1200.0, 2400.0, 3600.0])
    dt0s = np.array([0.5, 3.0, -2.0])
    t, temp_ref, grad_ref = ode_trajectories(knots_t, knots_tk, taus, dt0s, t0_c=18.0)
    temp, grad = _lag_samples(durations, rates, 20.0, 18.0, taus / 60.0, dt0s, t)
    np.testing.assert_allclose(temp, temp_ref, atol=1e-8)
    np.testing.assert_allclose(grad, grad_ref, atol=1e-8)


def test_pass_gradients_are_the_passes_a_plain_loop_finds(rng):
    """Every scenario's passes per bin: the same means as a plain loop finds, none lost at
    the row boundaries (a scenario ending in a bin the next one starts in)."""
    n_s, n_t, lo, nb = 4, 400, -3.0, 5
    temp = lo + nb / 2 + np.cumsum(rng.normal(0, 0.35, (n_s, n_t)), axis=1)
    temp[1] = temp[0, -1] - np.cumsum(np.full(n_t, 1e-3))  # starts where row 0 ends
    grad = rng.normal(0, 1, (n_s, n_t))
    got = pass_gradients(temp, grad, lo, nb)
    for s in range(n_s):
        want = _plain_passes(temp[s], grad[s], lo, nb)
        for b in range(nb):
            row = got[s * nb + b]
            np.testing.assert_allclose(row[np.isfinite(row)], want[b], atol=1e-12)


def test_separation_is_the_level_separation_of_every_row(rng):
    """The vectorised bisection agrees with coverage.level_separation (to its 1e-4
    degC/min), rows with too few passes give 0."""
    grads = rng.uniform(-1, 1, (300, 7))
    grads[rng.random(grads.shape) < 0.3] = np.nan
    for levels in (2, 3, 5):
        got = separation(grads, levels)
        for row, value in zip(grads, got, strict=True):
            want = level_separation(row[np.isfinite(row)], levels)
            assert value == pytest.approx(0.0 if np.isnan(want) else want, abs=2e-4)


# the red team's r10 (data/robust_hand/README.md): the band search falls back (its worst
# box point 0 %); the red team's hand table covers the box in 190 min
R10 = dict(working=(-10.0, -5.0), levels=3, tau_s=(1500.0, 3300.0), dt0_c=(0.5, 5.5))
R10_LIMITS = Limits(duration_max_min=200.0)


def _r10_spec():
    lo, hi = R10["working"]
    return ExperimentSpec(
        name="r10",
        working_lo_c=lo,
        working_hi_c=hi,
        approx_lo_c=lo - 10,
        approx_hi_c=hi + 10,
        levels_required=R10["levels"],
    )


@pytest.fixture(scope="module")
def r10_ramp():
    return ramp_search(_r10_spec(), ThermalParams(), R10_LIMITS, R10["tau_s"], R10["dt0_c"])


def test_ramp_rung_covers_a_box_the_band_search_falls_back_on(r10_ramp, tmp_path):
    """r10: a ramp programme within every limit whose coverage holds over the whole box,
    by scipy's ODE solver at points the rung never screened."""
    assert r10_ramp is not None
    spec = _r10_spec()
    assert r10_ramp.box_check["holds"] and r10_ramp.box_check["grid_points"] == 25 * 19
    csv = r10_ramp.programme.to_csv(tmp_path / "ramp.csv")
    got = box_table_check(
        csv, R10["working"], spec.delta_c_per_min, R10["tau_s"], R10["dt0_c"], R10_LIMITS.t_init_c
    )
    assert got["fewest_levels"] >= spec.levels_required
    assert R10_LIMITS.device_min_c <= got["device_c"][0]
    assert got["device_c"][1] <= R10_LIMITS.device_max_c
    assert got["duration_min"] <= R10_LIMITS.duration_max_min
    assert R10_LIMITS.rate_min_c_per_min - 1e-9 <= got["rates"][0]
    assert got["rates"][1] <= R10_LIMITS.rate_max_c_per_min + 1e-9
    assert got["ends_c"][0] == pytest.approx(20.0)
    assert abs(got["ends_c"][1] - 20.0) <= R10_LIMITS.end_tol_c


def test_ramp_rung_gives_up_within_its_budget():
    """A budget too small to find anything: None, not a partial programme."""
    spec = _r10_spec()
    found = ramp_search(spec, ThermalParams(), R10_LIMITS, R10["tau_s"], R10["dt0_c"], max_evals=60)
    assert found is None


def test_planner_plans_the_box_with_the_ramp_rung(r10_ramp):
    """plan_experiment: the band search finds no programme for r10's box, the ramp rung
    does (before the inner boxes are searched); the plan is complete for the whole box and
    says how it was made."""
    said: list[str] = []
    plan = plan_experiment(
        _r10_spec(),
        ThermalParams(),
        R10_LIMITS,
        robust_tau_s=R10["tau_s"],
        robust_dt0_c=R10["dt0_c"],
        progress=said.append,
    )
    assert plan.complete and plan.box_check["holds"] and plan.robust_fallback is None
    # the rung comes before the inner boxes, which could only answer for a part
    assert any("searching ramp programmes" in m for m in said)
    assert not any("inner half" in m or "inner quarter" in m for m in said)
    assert any(n.startswith("planned by the ramp rung") for n in plan.notes)
    assert not any(n.startswith("FALLBACK") for n in plan.notes)
    assert plan.duration_min == r10_ramp.programme.total_min  # the same deterministic search


def test_hand_table_request_matches_the_readme():
    """The r10 request above is the one data/robust_hand/ records for its hand table."""
    meta = read_step_meta(HAND / "r10_hand_190min.csv")
    assert (meta.working_lo_c, meta.working_hi_c) == R10["working"]
    assert meta.levels_required == R10["levels"]
    assert meta.robust_box == (R10["tau_s"], R10["dt0_c"])
    assert meta.duration_max_min == R10_LIMITS.duration_max_min


# the red team's r03: [-50, -47] degC 2 degC above the device's floor, dT0 1-5 degC
R03 = ExperimentSpec("r03", -50.0, -47.0, -52.0, -37.0, levels_required=3)


def test_a_box_no_programme_covers_is_proven_so_and_the_proof_holds_on_any_programme(rng):
    """r03: the proof names the bottom bin and device_min_c; its claim, checked by scipy's
    ODE solver on the fastest cooling path and on random programmes: whenever the warmer
    device (dT0 5) is in the bottom bin, the colder (dT0 1) is below the bound the proof
    gives, which is past device_min_c."""
    limits = Limits()
    proof = box_spread_proof(R03, ThermalParams(), limits, None, (1.0, 5.0))
    assert proof is not None and proof.startswith(NO_PROGRAMME_COVERS_BOX)
    assert "bottom bin" in proof and "device_min_c = -52" in proof
    bound_c = float(re.search(r"the colder is then below (-?[\d.]+) °C", proof).group(1))
    assert bound_c < limits.device_min_c
    fastest = [(90.0, -1.0), (450.0, 0.0)]  # -1 degC/min to the -70 degC floor, then held
    programmes = [fastest]
    for _ in range(40):  # random programmes within the limits, most reaching the floor
        down = float(rng.uniform(-1.0, -0.8))  # to the floor, held there a while
        steps = [(-90.0 / down, down), (float(rng.uniform(30, 150)), 0.0)]
        tk = -70.0
        for _ in range(int(rng.integers(2, 7))):
            dur = float(rng.uniform(10, 120))
            rate = float(rng.uniform(max(-1.0, (-70 - tk) / dur), min(3.0, (80 - tk) / dur)))
            steps.append((dur, rate))
            tk += dur * rate
        programmes.append(steps)
    entered = 0
    for steps in programmes:
        knots_t = np.concatenate(([0.0], np.cumsum([d for d, _ in steps])))
        knots_tk = 20.0 + np.concatenate(([0.0], np.cumsum([d * r for d, r in steps])))
        _, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, np.array([1.0, 5.0]))
        inside = temp[1] < R03.working_lo_c + 1.0
        if inside.any():
            entered += 1
            # the colder device is below the proof's bound whenever the warmer is in the
            # bin (the bound is past the limit)
            assert temp[0][inside].max() < bound_c + 1e-6
    assert entered >= 20  # (the check saw the warmer device in the bin)


def test_the_proof_names_the_top_bin_near_the_device_ceiling():
    """[57, 61] degC below the 62 degC ceiling, dT0 1-5 degC: the colder device in the top
    bin takes the warmer past device_max_c."""
    spec = ExperimentSpec("hot", 57.0, 61.0, 47.0, 62.0, levels_required=3)
    proof = box_spread_proof(spec, ThermalParams(), Limits(), None, (1.0, 5.0))
    assert proof is not None and "top bin" in proof and "device_max_c = 62" in proof


def test_no_proof_for_boxes_a_programme_covers(r10_ramp):
    """r10 (the ramp rung covers it) and r03 with a narrow dT0 range: no proof."""
    assert r10_ramp is not None
    assert (
        box_spread_proof(_r10_spec(), ThermalParams(), R10_LIMITS, R10["tau_s"], R10["dt0_c"])
        is None
    )
    assert box_spread_proof(R03, ThermalParams(), Limits(), None, (2.0, 4.0)) is None


def test_every_parameter_vector_decodes_to_a_programme_within_the_rate_limits(rng):
    """The family's decoding (what the optimiser explores): random and extreme parameters
    give a programme, each rate within the chamber's limits, each turn within its
    temperature limits, ending at the end temperature."""
    from schedsyn.planner.ramps import _Family

    limits = Limits(rate_min_c_per_min=-0.8, chamber_min_c=-40.0, chamber_max_c=70.0)
    spec = ExperimentSpec("mid", 19.0, 21.0, 10.0, 30.0, levels_required=4)
    for legs, first in ((4, -1), (5, 1)):
        family = _Family(spec, limits, legs, first, (1800.0, 3000.0), (1.0, 4.0))
        for x in [*rng.normal(0, 4, (200, family.n)), np.full(family.n, -40.0)]:
            prog = family.programme(x)
            assert np.all(prog.rates_c_per_min >= limits.rate_min_c_per_min - 1e-9)
            assert np.all(prog.rates_c_per_min <= limits.rate_max_c_per_min + 1e-9)
            tk = prog.boundary_temps_c
            assert tk.min() >= limits.chamber_min_c - 1e-9
            assert tk.max() <= limits.chamber_max_c + 1e-9
            assert abs(prog.end_c - limits.end_c) < 1e-6
