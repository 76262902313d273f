"""Stage 6: the whole-programme LPs -- margins, then the fewest rate changes.

With the sweep windows fixed by the search, one LP over the whole programme maximises the
margins (passes deeper inside their bands, sweeps further beyond the region edges), then a
second keeps most of that margin and minimises the total rate change, so the exported step
table stays short.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

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
#: Rates closer than this are one step of the table, degC/min.
STEP_RATE_TOL_C_PER_MIN = 1e-6
#: Rounds of merging steps that a merge left too short.
MERGE_ROUNDS = 3
#: Merges beyond the fewest needed that are tried when those fail (rounding, ties).
MERGE_EXTRA = (0, 2, 5)


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
    rates and the two margins (the search's own rates and zero margins when the margin LP
    is not solved).
    """
    res = polish_tied(ctx, structure, frozenset())
    return res if res is not None else (structure.u, 0.0, 0.0)


def polish_tied(
    ctx: Context, structure: Structure, ties: frozenset[int]
) -> tuple[np.ndarray, float, float] | None:
    """:func:`polish` with ``ties``: free segments ``j`` whose rate must equal segment
    ``j + 1``'s (merged steps, see :func:`honour_step_limits`); None when not solved."""
    lp = whole_lp(ctx, structure.windows, structure.n_seg, extra=2)
    n = lp.n
    first = ctx.responses.n_fixed
    tied = sorted(j - first for j in ties if first <= j < first + n - 1)

    def tie_rows(x: cp.Variable) -> list:
        return [x[j] == x[j + 1] for j in tied]

    g_cap, t_cap = MARGIN_G_CAP_C_PER_MIN, MARGIN_T_CAP_C
    x = lp.solve(
        lambda x: -(x[-2] / g_cap + MARGIN_T_WEIGHT * x[-1] / t_cap),
        [(0.0, g_cap), (0.0, t_cap)],
        tie_rows if tied else None,
    )
    ctx.size = lp.last_size
    if x is None:
        return None
    best_g, best_t = x[-2], x[-1]
    x2 = lp.solve(
        lambda x: cp.norm1(cp.diff(x[:n])),
        [(MARGIN_KEEP * best_g, g_cap), (MARGIN_KEEP * best_t, t_cap)],
        tie_rows if tied else None,
    )
    if x2 is not None:
        x = x2
    return np.concatenate((ctx.responses.fixed_rates, x[:n])), float(x[-2]), float(x[-1])


def step_runs(u: np.ndarray, tol: float = STEP_RATE_TOL_C_PER_MIN) -> list[tuple[int, int]]:
    """``(first, last)`` segment of each run of equal rates (one step of the table)."""
    runs, start = [], 0
    for j in range(1, u.size + 1):
        if j == u.size or abs(u[j] - u[start]) > tol:
            runs.append((start, j - 1))
            start = j
    return runs


def _tied(
    ctx: Context,
    structure: Structure,
    ties: set[int],
    short_seg: int,
) -> tuple[np.ndarray, float, float] | None:
    """Re-polish with ``ties``, then with steps shorter than ``short_seg`` segments tied to
    their closer neighbour too (merging can leave new short ones: a few rounds)."""
    first = ctx.responses.n_fixed
    res = None
    for _ in range(MERGE_ROUNDS):
        res = polish_tied(ctx, structure, frozenset(ties))
        if res is None:
            return None
        more = set()
        for a, b in step_runs(res[0]):
            if a < first or b - a + 1 >= short_seg:
                continue
            left = abs(res[0][a] - res[0][a - 1]) if a > first else np.inf
            right = abs(res[0][b] - res[0][b + 1]) if b + 1 < res[0].size else np.inf
            more |= set(range(a, b)) | ({a - 1} if left <= right else {b})
        more = {j for j in more if first <= j < res[0].size - 1} - ties
        if not more:
            break
        ties |= more
    return res


def honour_step_limits(
    ctx: Context,
    structure: Structure,
    u: np.ndarray,
    accept: Callable[[np.ndarray], bool],
    max_steps: int,
    min_step_seg: int = 1,
) -> tuple[np.ndarray, float, float] | None:
    """Fewer, longer steps: the table may have at most ``max_steps`` steps, none shorter
    than ``min_step_seg`` segments.

    Neighbouring steps are merged by tying their rates in the whole-programme LPs (the
    windows stay, so every band constraint still holds): the boundaries between the steps
    whose rates differ least go first, as many as the limit needs, and every step too
    short is tied to the neighbour whose rate is closer. The result counts only if
    ``accept(u)`` (the caller re-checks the rounded table); a few more merges are tried
    when rounding or a tie set fails. None when nothing meets the limits.
    """
    first = ctx.responses.n_fixed
    runs = step_runs(u)
    keep = {j for a, b in runs for j in range(a, b) if a >= first}  # merges already made
    ranked = sorted(
        (abs(u[b[0]] - u[a[1]]), a[1])
        for a, b in zip(runs[:-1], runs[1:], strict=False)
        if a[1] >= first
    )
    need = max(0, len(runs) - max_steps)
    for extra in MERGE_EXTRA:
        ties = keep | {j for _, j in ranked[: need + extra]}
        res = _tied(ctx, structure, ties, min_step_seg)
        if res is None:
            continue
        done = step_runs(res[0])
        short = any(b - a + 1 < min_step_seg for a, b in done if a >= first)
        if len(done) <= max_steps and not short and accept(res[0]):
            return res
    return None


def merge_small_changes(
    ctx: Context,
    structure: Structure,
    u: np.ndarray,
    accept: Callable[[np.ndarray], bool],
    min_change_c: float,
) -> tuple[np.ndarray, float, float] | None:
    """Merge steps that change the setpoint by less than ``min_change_c`` into a neighbour
    (an operator types fewer, more meaningful steps) -- only if ``accept`` still holds."""
    first = ctx.responses.n_fixed
    d = ctx.responses.durations
    runs = step_runs(u)
    ties = {j for a, b in runs for j in range(a, b) if a >= first}
    small = False
    for i, (a, b) in enumerate(runs):
        change = abs(float(u[a]) * float(d[a : b + 1].sum()))
        if a < first or change >= min_change_c:
            continue
        left = abs(u[a] - u[runs[i - 1][1]]) if i > 0 and runs[i - 1][1] >= first else np.inf
        right = abs(u[b] - u[runs[i + 1][0]]) if i + 1 < len(runs) else np.inf
        if min(left, right) == np.inf:
            continue
        ties |= set(range(a, b)) | ({a - 1} if left <= right else {b})
        small = True
    if not small:
        return None
    res = polish_tied(ctx, structure, frozenset(j for j in ties if first <= j < u.size - 1))
    return res if res is not None and accept(res[0]) else None
