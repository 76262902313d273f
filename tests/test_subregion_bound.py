"""A region far too wide for the time gets a partial plan for the part that fits, not a
refusal (schedsyn.planner.search.subregions, SUBREGION_BOUND_SHARES).

Red team: [-51, 19] degC, 3 levels in 200 min (bound 384 min) was refused with "no
programme covers any part" and exit 2, although [10, 19] plans complete in 144 min: the
usual sub-regions cut at most 45 % of the bins. Truth: scipy's integration of the
exported table (tests/independent.py).
"""

from __future__ import annotations

import pytest
from independent import table_check

from schedsyn import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, plan_experiment, search

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")


def test_a_region_far_too_wide_for_the_time_gets_the_widest_part_the_bound_allows(tmp_path):
    """[-30, 19] degC at 2 levels in 100 min (bound 131 min): no usual sub-region (cut
    at most 22 of 49 bins) fits. The bound-guided cut plans sweeps for the warm end; the
    table passes every bin of that part twice by scipy, and the plan says which part."""
    assert search.SUBREGION_BOUND_SHARES  # the guard under test is on
    spec = ExperimentSpec("S", -30.0, 19.0, -32.0, 21.0, levels_required=2)
    limits = Limits(duration_max_min=100.0)
    plan = plan_experiment(spec, ThermalParams(), limits, effort_s=5)
    assert not plan.complete
    (note,) = [n for n in plan.notes if n.startswith("sweeps designed for the sub-region")]
    lo, hi = (float(x) for x in note.split("[", 1)[1].split("]", 1)[0].split(","))
    assert -30.0 < lo < hi <= 19.0 and hi - lo <= 0.55 * 49  # narrower than any usual cut
    plan.programme.to_csv(tmp_path / "steps.csv")
    truth = table_check(tmp_path / "steps.csv", (-30.0, 19.0), 2)
    assert truth["coverage"] == pytest.approx(plan.coverage.coverage)
    assert truth["duration_min"] <= 100.0 + 1e-9
    levels = truth["levels"]
    part = levels[int(lo + 30.0) : int(hi + 30.0)]
    assert part.size > 0 and (part >= 2).all(), levels
