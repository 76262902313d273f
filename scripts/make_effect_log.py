"""Write a synthetic measured log with one hidden effect (for trying `schedsyn diagnose`).

    python scripts/make_effect_log.py EFFECT [NAME=VALUE ...] [--steps STEPS.csv]
        [--tau-s 2400] [--dt0-c 3] [--sample-s 10] [--noise-c 0.02] [--quant-c 0.01]
        [--no-air] [--seed 0] --out LOG.csv

EFFECT is `none` or a name from schedsyn.effects.EFFECTS; NAME=VALUE sets its parameters
(all are needed, e.g. `chamber_cycling amplitude_c=1 period_s=900 phase_rad=0`). The
steps default to data/baseline_exp1_steps.csv. The truth columns (t_true_c,
g_true_c_per_min) are dropped: the log looks like a real one.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from schedsyn import read_steps
from schedsyn.effects import ModelSpec
from schedsyn.synth import synth_effect_log

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("effect")
    ap.add_argument("params", nargs="*", metavar="NAME=VALUE")
    ap.add_argument("--steps", default=str(ROOT / "data" / "baseline_exp1_steps.csv"))
    ap.add_argument("--tau-s", type=float, default=2400.0)
    ap.add_argument("--dt0-c", type=float, default=3.0)
    ap.add_argument("--sample-s", type=float, default=10.0)
    ap.add_argument("--noise-c", type=float, default=0.02)
    ap.add_argument("--quant-c", type=float, default=0.01)
    ap.add_argument("--no-air", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    params = {k: float(v) for k, v in (p.split("=", 1) for p in args.params)}
    truth = ModelSpec(args.tau_s, args.dt0_c, args.effect, params)
    frame = synth_effect_log(
        read_steps(args.steps),
        truth,
        sample_s=args.sample_s,
        noise_c=args.noise_c,
        quant_c=args.quant_c,
        seed=args.seed,
        with_air=not args.no_air,
    )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    frame.drop(columns=["t_true_c", "g_true_c_per_min"]).to_csv(args.out, index=False)
    print(f"wrote {args.out}: {len(frame)} rows, hidden effect {truth.effect} {params}")


if __name__ == "__main__":
    main()
