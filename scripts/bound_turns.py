"""Does coupling the turns tighten the duration bound? (docs/planner.md, the bound)

The bound charges a turn as the braking sweep's stopping time plus the next sweep's
speeding-up time, each from its own edge speed. In truth the next sweep must also come
back over the first one's overshoot: the turn takes at least ``stop(a) + max(cover(stop
distance(a)), speed-up(b))``. This script solves one heating and one cooling rank coupled
that way at both edges, exactly on the bound's grid (each rank's least crossing time for
every pair of edge-bin speeds, then minima over the couplings by prefix and suffix
minima), and prints it beside the two ranks solved apart. Levels and roles are left out:
it asks only whether the coupling moves the optimum.

    python scripts/bound_turns.py w2 m30-m10-360      # names of data/bench/ files

It printed the same value both ways for W2 (114.6 min) and [-30, -10] °C (92.4 / 92.5).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from schedsyn.campaign import load_campaign
from schedsyn.planner.bound import (
    GRID_C_PER_MIN,
    GRID_PER_DELTA,
    _caps,
    _Curves,
    _range_min,
    _range_plan,
    _sides,
)
from schedsyn.planner.physics import accel_time, speed_after_accel, stop_distance, stop_time

BENCH = Path(__file__).resolve().parents[1] / "data" / "bench"


def pair(name: str) -> tuple[float, float]:
    """(ranks apart, ranks coupled at both turns), min."""
    config = load_campaign(BENCH / f"{name}.toml")
    spec, params, limits = config.experiments[0], config.params, config.limits
    tau, w = params.tau_min, spec.grid.bin_c
    sides = _sides(params, limits)
    step = min(GRID_C_PER_MIN, spec.delta_c_per_min / GRID_PER_DELTA)
    v_top = max(s.r_fwd for s in sides.values())
    v = step * np.arange(1, int(math.ceil(v_top / step)) + 1)
    g = v.size
    info = {}
    for d, side in sides.items():
        c = _Curves(side, w, tau, v_top + step)
        up = np.ceil(np.maximum(c.fastest_next(v), v) / step) * step
        down = np.floor(np.minimum(c.slowest_next(np.maximum(v - step, 0.0)), v) / step) * step
        lo = np.searchsorted(up, v - 1e-12, side="left")
        hi = np.minimum(np.searchsorted(down, v + 1e-12, side="right") - 1, g - 1)
        caps = np.ceil(_caps(spec, params, limits, side, False) / step) * step
        plan = _range_plan(lo, hi)
        cost = np.full((g, g), np.inf)  # [first-bin speed, current speed]
        ok = np.flatnonzero(v <= caps[0])
        cost[ok, ok] = w / v[ok]
        for j in range(1, caps.size):
            cost = np.where(v <= caps[j], _range_min(cost, lo, hi, plan) + w / v, np.inf)
        v_in = c.entry_speed(np.maximum(v - step, 0.0))
        v_out = c.exit_speed(np.maximum(v - step, 0.0))
        info[d] = (cost, v_in, v_out)

    def turn(exiting: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stop time and return over the overshoot (by exit speed), speed-up time (by
        the next sweep's entry speed)."""
        r = sides[exiting].r_back
        v_out, v_in = info[exiting][2], info[-exiting][1]
        back = stop_distance(v_out, r, tau)
        cover = accel_time(speed_after_accel(np.zeros_like(back), back, r, tau), r, tau)
        return stop_time(v_out, r, tau), cover, accel_time(v_in, r, tau)

    def couple(f: np.ndarray, stop: np.ndarray, c: np.ndarray, e: np.ndarray) -> np.ndarray:
        """``M[i, k] = min_o f[i, o] + stop[o] + max(c[o], e[k])`` (c and e increasing)."""
        order = np.argsort(c, kind="stable")
        p = (f + stop)[:, order]
        q = (f + stop + c)[:, order]
        p_pre = np.minimum.accumulate(p, axis=1)
        q_suf = np.minimum.accumulate(q[:, ::-1], axis=1)[:, ::-1]
        t = np.searchsorted(c[order], e, side="right")
        m = np.full((f.shape[0], e.size), np.inf)
        m[:, t > 0] = p_pre[:, t[t > 0] - 1] + e[t > 0]
        m[:, t < g] = np.minimum(m[:, t < g], q_suf[:, t[t < g]])
        return m

    (f_h, *_), (f_c, *_) = info[+1], info[-1]
    s_top, c_top, e_top = turn(+1)  # heating leaves at the top, cooling comes in
    s_bot, c_bot, e_bot = turn(-1)
    coupled = float(np.min(couple(f_h, s_top, c_top, e_top) + couple(f_c, s_bot, c_bot, e_bot).T))
    apart = float(np.min(f_h + e_bot[:, None] + s_top) + np.min(f_c + e_top[:, None] + s_bot))
    return apart, coupled


def main(names: list[str]) -> int:
    if not names:
        print("usage: python scripts/bound_turns.py NAME ... (data/bench/ names)", file=sys.stderr)
        return 2
    for name in names:
        if not (BENCH / f"{name}.toml").is_file():
            print(f"no request {name!r} in {BENCH}", file=sys.stderr)
            return 2
        apart, coupled = pair(name)
        print(f"{name}: ranks apart {apart:.1f} min, coupled at both turns {coupled:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
