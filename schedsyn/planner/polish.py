"""Stage 6: the whole-programme LPs -- margins, then the fewest rate changes.

With the sweep windows fixed by the search, one LP over the whole programme maximises the
margins (passes deeper inside their bands, sweeps further beyond the region edges), then a
second keeps most of that margin and minimises the total rate change, so the exported step
table stays short.
"""

from __future__ import annotations

from collections.abc import Sequence

import cvxpy as cp
import numpy as np

from .lp import Context, SubLP, Window
from .search import Structure

#: Largest margins worth having: beyond these they would only slow the programme.
MARGIN_G_CAP_C_PER_MIN = 0.03
MARGIN_T_CAP_C = 1.0
#: Relative weight of the edge margin against the band margin (each scaled by its cap).
MARGIN_T_WEIGHT = 0.5
#: Share of the best margins the fewest-changes LP must keep.
MARGIN_KEEP = 0.8


def whole_lp(ctx: Context, windows: Sequence[Window], n_seg: int, extra: int = 0) -> SubLP:
    """The LP over the whole programme with the given sweep windows (margins optional).

    A continuation's executed steps are fixed: only the segments after them are free.
    """
    lp = SubLP(ctx, ctx.responses.fixed_rates, n_seg, extra=extra)
    lp.chamber()
    lp.chamber_end(ctx.limits.end_c)
    lp.device()
    for w in windows:
        if extra:
            lp.window(w, margin_g=0, margin_t=1)
        else:
            lp.window(w)
    return lp


def polish(ctx: Context, structure: Structure) -> tuple[np.ndarray, float, float]:
    """Whole-programme LPs with the windows fixed: maximise margin, then fewest changes.

    Margins: ``margin_g`` shrinks every band from both sides (passes further apart than
    delta), ``margin_t`` pushes every sweep further beyond the region edges. Returns the
    rates and the two margins (zero, and the search's rates, when the margin LP is not
    solved).
    """
    lp = whole_lp(ctx, structure.windows, structure.n_seg, extra=2)
    g_cap, t_cap = MARGIN_G_CAP_C_PER_MIN, MARGIN_T_CAP_C
    x = lp.solve(
        lambda x: -(x[-2] / g_cap + MARGIN_T_WEIGHT * x[-1] / t_cap),
        [(0.0, g_cap), (0.0, t_cap)],
    )
    ctx.size = lp.last_size
    if x is None:
        return structure.u, 0.0, 0.0
    best_g, best_t = x[-2], x[-1]
    n = lp.n
    x2 = lp.solve(
        lambda x: cp.norm1(cp.diff(x[:n])),
        [(MARGIN_KEEP * best_g, g_cap), (MARGIN_KEEP * best_t, t_cap)],
    )
    if x2 is not None:
        x = x2
    return np.concatenate((ctx.responses.fixed_rates, x[:n])), float(x[-2]), float(x[-1])
