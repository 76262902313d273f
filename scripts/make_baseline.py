"""Write the hand-made, paper-like baseline programme for experiment 1 (data/).

The paper's experiment 1: from +20 degC the chamber cools the device to the bottom of the
approximation region [-52, -20] degC, then three heating and two cooling cycles, back to
20 degC within 9 h. The turning points and rates below were chosen by hand (a coarse
trial-and-error search, as in the paper) so that the device stays inside [-52, +20] degC.

Run: python scripts/make_baseline.py [OUT.csv]
"""

import sys
from pathlib import Path

import numpy as np

import schedsyn

# (chamber target degC, ramp rate magnitude degC/min, hold after reaching it min)
SPEC = [
    (-67.0, 1.0, 27),  # cool the device towards -52 degC
    (-14.0, 2.0, 44),  # heating 1
    (-60.0, 0.9, 26),  # cooling 1
    (-12.0, 1.4, 17),  # heating 2
    (-63.0, 0.9, 39),  # cooling 2
    (20.0, 2.7, 57),  # heating 3, back to 20 degC
]


def baseline_programme() -> schedsyn.Programme:
    durations, rates, current = [], [], 20.0
    for target, rate, hold in SPEC:
        durations.append(abs(target - current) / rate)
        rates.append(np.sign(target - current) * rate)
        current = target
        durations.append(float(hold))
        rates.append(0.0)
    return schedsyn.Programme(np.array(durations), np.array(rates)).rounded(schedsyn.Limits())


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("data/baseline_exp1_steps.csv")
    programme = baseline_programme()
    programme.to_csv(out)
    print(f"wrote {out}: {programme.n_segments} steps, {programme.total_min:.0f} min")
