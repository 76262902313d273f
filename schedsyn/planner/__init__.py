"""Synthesis of chamber programmes that cover a working region with distinct gradients.

The method (design note: ``docs/planner.md``)
---------------------------------------------
Decision variables are the ramp rates ``u_j`` of fixed-length segments (``segment_min``).
By :func:`schedsyn.model.affine_response`, the internal temperature ``T_i`` and gradient
``g_i`` at every planner sample (every minute) are affine in ``u``, so every requirement
below is a linear constraint:

* rates within ``[rate_min, rate_max]``; chamber temperature at every boundary within
  the chamber limits; ``Tk(end) = end_c``; device temperature within its limits;
* **sweeps**: the programme is a sequence of ``levels_required`` monotone sweeps across
  the working region, alternating cooling and heating. Sweep ``k`` owns a time window;
  at its ends the device lies beyond the region's edges by ``edge_margin_c``, and inside
  it the direction-signed gradient ``q = d * g`` lies in a **band** ``l_r(T) <= q_i <=
  v_r(T)``, piecewise linear in T: the sweep crosses each inner knot at a planned sample,
  so each stretch is held to one affine piece -- linear because both ``q_i`` and ``T_i``
  are affine in ``u``. The bands of one direction are disjoint by ``delta`` plus a safety
  gap at every temperature, and heating and cooling bands are apart by at least
  ``delta``; every pass of a bin is a mean of samples inside its sweep's band, so each bin
  gets ``levels_required`` passes pairwise ``delta`` apart.
* The bands follow the physics (:mod:`.physics`): the chamber limits bound the gradient
  available at each temperature, the device must turn round before its own limits, and a
  sweep cannot change speed faster than the chamber rates allow.

The combinatorial part -- where each sweep's window starts and ends -- is found by a
greedy search in time (:mod:`.search`); a final LP over the whole programme keeps those
windows and maximises the margin, then a second minimises the rate changes
(:mod:`.polish`). The exported step table (whole minutes, 0.1 degC) is re-simulated
densely and its coverage recomputed by :mod:`schedsyn.coverage`; a plan is called
complete only on that independent check (:mod:`.check`).

A proven lower bound on the duration of any complete plan (:mod:`.bound`) is computed from
the physics alone, independently of the search, and reported with every plan.

The stages, one module each, imports flowing one way::

    request -> physics -> bands -> lp -> search -> polish -> check -> robust -> core
    (spec,     (speed    (levels   (rows,  (sweep    (margin,  (Plan,   (box,     (plan_
     limits)    limits)   per sweep) solving) windows) fewest    dense    fallback) experiment)
                                                      changes)  check)
"""

from .bands import BAND_SAFETY_C_PER_MIN, DESIGNS, Band, BandDesign, make_bands, order_bands
from .bound import DurationBound, duration_lower_bound
from .check import Plan, check_programme
from .core import plan_experiment
from .explain import explain_shortfall
from .lp import LpStats
from .physics import turning_speed
from .request import (
    OBJECTIVES,
    Continuation,
    ExperimentSpec,
    Scenario,
    check_device_start,
    check_request,
    check_start_excursion,
    planning_effort,
    robust_scenarios,
    start_excursion_c,
)
from .robust import robustness_price

__all__ = [
    "BAND_SAFETY_C_PER_MIN",
    "DESIGNS",
    "OBJECTIVES",
    "Band",
    "BandDesign",
    "Continuation",
    "DurationBound",
    "ExperimentSpec",
    "LpStats",
    "Plan",
    "Scenario",
    "check_programme",
    "check_device_start",
    "check_request",
    "check_start_excursion",
    "duration_lower_bound",
    "explain_shortfall",
    "make_bands",
    "start_excursion_c",
    "order_bands",
    "plan_experiment",
    "planning_effort",
    "robust_scenarios",
    "robustness_price",
    "turning_speed",
]
