"""The search places each sweep once per synthesis for the same arguments.

The slow retry runs a stuck candidate's greedy again; its sweeps before the stuck one,
and the stuck one's usual timings, are the searches it already made. They are answered
from the first search (:func:`schedsyn.planner.search._place_sweep_once`), which must
change neither the answer nor the effort the search counts (an effort limit must cut
where it did).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from schedsyn import Limits, ThermalParams
from schedsyn.model import FirstOrderLag
from schedsyn.planner import ExperimentSpec
from schedsyn.planner import search as search_module
from schedsyn.planner.lp import LpStats, lp_nonzeros_solved

PARAMS = ThermalParams()


def _synthesise(spec, limits, max_candidates):
    stats = LpStats()
    work0 = lp_nonzeros_solved()
    found = search_module.synthesise(
        spec, [PARAMS], limits, [FirstOrderLag(PARAMS)], None, stats, max_candidates
    )
    return found, stats, lp_nonzeros_solved() - work0


def _structure(s):
    if s is None:
        return None
    return (s.n_seg, np.round(s.u, 9).tolist(), [w.pieces() for w in s.windows])


@pytest.mark.parametrize(
    "duration_min, segment_min, max_candidates",
    [
        # one candidate, stuck on its last sweep: the retry re-places the first one
        (80.0, 3.0, 1),
        # every candidate, all stuck
        (80.0, 3.0, None),
        # every candidate: one finds a structure too long, and the limit the later
        # candidates (and the retry) search within shrinks to it
        (90.0, 5.0, None),
    ],
)
def test_a_repeated_sweep_search_gives_the_same_answer_and_counts_the_same_work(
    monkeypatch, duration_min, segment_min, max_candidates
):
    spec = ExperimentSpec("m", -5.0, 0.0, -15.0, 10.0, levels_required=2, segment_min=segment_min)
    limits = Limits(duration_max_min=duration_min)
    found, stats, work = _synthesise(spec, limits, max_candidates)
    assert stats.sweeps_reused > 0  # the retry happened and reused sweeps
    assert (found.overrun is not None) == (duration_min == 90.0)  # the case is as meant

    def every_time(ctx, u_fixed, d, band, max_seg, slow, every_sample=False, pinned=False):
        return search_module.place_sweep(
            ctx, u_fixed, d, band, max_seg, slow=slow, every_sample=every_sample, pinned=pinned
        )

    monkeypatch.setattr(search_module, "_place_sweep_once", every_time)
    again, stats_again, work_again = _synthesise(spec, limits, max_candidates)
    assert stats_again.sweeps_reused == 0
    assert stats.solves < stats_again.solves  # the reused sweeps solved no LP
    assert work == work_again  # ... but count the work they stood for
    assert found.reasons == again.reasons
    assert (found.best is None) == (again.best is None)
    assert _structure(found.best and found.best[0]) == _structure(again.best and again.best[0])
    assert _structure(found.overrun) == _structure(again.overrun)


def test_only_the_same_fixed_rates_band_limit_and_timing_are_answered_from_memory(monkeypatch):
    """The key: a sweep searched within another segment limit, after other fixed rates,
    in another band, with the other timings, scanned minute by minute or with its edge bins
    pinned is searched again."""
    calls = []

    def fake(ctx, u_fixed, d, band, max_seg, slow=False, every_sample=False, pinned=False):
        calls.append((u_fixed.tolist(), d, band, max_seg, slow, every_sample, pinned))
        return None if slow else (np.full(2, float(len(calls))), None)

    monkeypatch.setattr(search_module, "place_sweep", fake)
    ctx = SimpleNamespace(sweep_memo={}, stats=LpStats())
    u, band = np.array([1.0, -1.0]), object()
    first = search_module._place_sweep_once(ctx, u, 1, band, 40, False)
    same = search_module._place_sweep_once(ctx, u.copy(), 1, band, 40, False)
    assert len(calls) == 1 and same is first and ctx.stats.sweeps_reused == 1
    for args in (
        (u, 1, band, 39, False),  # another limit
        (u, 1, band, 40, True),  # slow timings
        (u, 1, band, 40, False, True),  # the window start scanned minute by minute
        (u, 1, band, 40, False, False, True),  # the edge bins pinned
        (u, -1, band, 40, False),  # the other direction
        (u, 1, object(), 40, False),  # another band
        (np.array([1.0, -0.5]), 1, band, 40, False),  # other fixed rates
    ):
        search_module._place_sweep_once(ctx, *args)
    assert len(calls) == 8 and ctx.stats.sweeps_reused == 1
