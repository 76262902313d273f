"""Blind benchmark of `schedsyn diagnose`: confusion matrix, parameter errors, run time.

Every case is a synthetic log (schedsyn.synth.blind_case) with one hidden effect drawn
from realistic ranges (or none), on one of three 9-hour programmes, diagnosed blind.

    python scripts/bench_diagnose.py [--seeds 10] [--clean 20] [--workers 2] [--out DIR]
        [--fit-step-s S]

Writes DIR/cases.csv (one row per log), DIR/confusion.csv, DIR/summary.csv and prints
the tables. A case is "correct" if the named effect is the truth, or if the truth is
listed in `ambiguous_with` because the channels present cannot tell them apart
(chamber_lag vs second_time_constant without the air channel, or lag-type effects that
fit nearly equally). ``named_strictly`` counts only the named effect; ``lag_ambiguous``
the logs where lag-type effects were listed as nearly equal; ``seen_in_air`` the logs
where the chamber-air channel showed an effect (reported with its device impact).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn import read_steps
from schedsyn.discrepancy import DiagnoseSettings, diagnose_frame
from schedsyn.effects import EFFECTS
from schedsyn.synth import blind_case, blind_programmes

ROOT = Path(__file__).resolve().parents[1]


def programmes():
    progs = dict(blind_programmes())
    progs["exp1"] = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    return progs


def main_error(effect: str, truth, found) -> float:
    """Relative error of the main parameter (asymmetric_tau: of tau_cool/tau_heat - 1)."""
    if effect == "asymmetric_tau":
        t = truth["tau_cool_s"] / truth["tau_heat_s"] - 1.0
        f = found["tau_cool_s"] / found["tau_heat_s"] - 1.0
        return abs(f - t) / abs(t)
    name = EFFECTS[effect].main_param
    key = name if name in found else next(iter(found))  # twin names (tau2 vs tau_chamber)
    return abs(found[key] - truth[name]) / abs(truth[name])


def run_case(args):
    effect, seed, fit_step_s = args
    progs = programmes()
    names = sorted(progs)
    prog_name = names[seed % len(names)]
    frame, truth, noise = blind_case(
        effect, 1000 * (list(EFFECTS) + ["none"]).index(effect) + seed, progs[prog_name]
    )
    t0 = time.perf_counter()
    d = diagnose_frame(frame, DiagnoseSettings(fit_step_s=fit_step_s))
    elapsed = time.perf_counter() - t0
    correct = d.effect == effect or (effect in d.ambiguous_with and effect != "none")
    err = float("nan")
    if correct and effect != "none":
        err = main_error(effect, truth.parameters, d.parameters)
    return {
        "truth": effect,
        "seed": seed,
        "programme": prog_name,
        "found": d.effect,
        "ambiguous_with": ",".join(d.ambiguous_with),
        "correct": correct,
        "named_strictly": d.effect == effect,
        # getattr: the same script runs on a version without these reports (before/after)
        "lag_ambiguity": ",".join(a.effect for a in getattr(d, "lag_ambiguity", ())),
        "seen_in_air": ",".join(f.effect for f in getattr(d, "air_findings", ())),
        "main_rel_error": err,
        "rms_before_c": d.rms_before_c,
        "rms_after_c": d.rms_after_c,
        "holdout_before_c": d.holdout_rms_before_c,
        "holdout_after_c": d.holdout_rms_after_c,
        "noise_c": noise,
        "sample_s": float(np.median(np.diff(frame["time_s"]))),
        "with_air": "tk_air_c" in frame,
        "seconds": elapsed,
        "truth_params": "; ".join(f"{k}={v:.4g}" for k, v in truth.parameters.items()),
        "found_params": "; ".join(f"{k}={v:.4g}" for k, v in d.parameters.items()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="logs per effect")
    ap.add_argument("--clean", type=int, default=20, help="logs without an effect")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--fit-step-s", type=float, default=None)
    ap.add_argument("--out", default="out/bench_diagnose")
    ns = ap.parse_args()
    jobs = [(e, s, ns.fit_step_s) for e in EFFECTS for s in range(ns.seeds)]
    jobs += [("none", s, ns.fit_step_s) for s in range(ns.clean)]
    t0 = time.perf_counter()
    # spawned workers: a forked child can inherit a held solver/BLAS lock and hang
    # (scripts/closed_loop.py sat for an hour on a futex that way)
    with ProcessPoolExecutor(ns.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        rows = list(pool.map(run_case, jobs))
    wall = time.perf_counter() - t0
    cases = pd.DataFrame(rows)
    out = Path(ns.out)
    out.mkdir(parents=True, exist_ok=True)
    cases.to_csv(out / "cases.csv", index=False)
    confusion = pd.crosstab(cases["truth"], cases["found"])
    confusion.to_csv(out / "confusion.csv")
    material = cases["rms_before_c"] > 3 * cases["noise_c"]
    cases["halved"] = cases["rms_after_c"] <= 0.5 * cases["rms_before_c"]
    summary = (
        cases.assign(material=material)
        .groupby("truth")
        .agg(
            n=("correct", "size"),
            correct=("correct", "sum"),
            named_strictly=("named_strictly", "sum"),
            lag_ambiguous=("lag_ambiguity", lambda s: int((s != "").sum())),
            seen_in_air=("seen_in_air", lambda s: int((s != "").sum())),
            main_err_median=("main_rel_error", "median"),
            main_err_max=("main_rel_error", "max"),
            within_25pct=("main_rel_error", lambda s: int((s <= 0.25).sum())),
            material=("material", "sum"),
            halved_of_material=("halved", lambda s: int(s[material[s.index]].sum())),
            seconds_median=("seconds", "median"),
            seconds_max=("seconds", "max"),
        )
    )
    summary.to_csv(out / "summary.csv")
    pd.set_option("display.width", 200)
    print(confusion.to_string())
    print()
    print(summary.to_string(float_format=lambda v: f"{v:.3g}"))
    print(
        f"\n{len(cases)} logs in {wall:.0f} s wall on {ns.workers} workers; "
        f"median {cases['seconds'].median():.1f} s per log (one core each)"
    )
    bad = cases[~cases["correct"]]
    if len(bad):
        print("\nmisses:")
        print(
            bad[
                [
                    "truth",
                    "seed",
                    "programme",
                    "found",
                    "with_air",
                    "sample_s",
                    "noise_c",
                    "truth_params",
                    "found_params",
                ]
            ].to_string()
        )


if __name__ == "__main__":
    main()
