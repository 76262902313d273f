"""Mutation check: plant known bugs one at a time and make sure the tests catch each.

Each mutation is (file, exact original text, mutated text, the tests expected to kill
it). For every mutation the script writes the mutated file, runs only its tests
(``pytest -x``), and restores the file byte for byte (also on Ctrl-C or SIGTERM; a copy
``<file>.mutation-backup`` lets the next run restore it even after a hard kill). First
it runs the same tests on the unmutated code (they must pass, or a "killed" mutant would
mean nothing).

    .venv/bin/python scripts/mutation_check.py               # all, a few minutes on 2 cores
    .venv/bin/python scripts/mutation_check.py --list        # the mutations
    .venv/bin/python scripts/mutation_check.py --only delta-0.9 bic-penalty

Writes ``out/mutation_check/mutation_check.md`` and ``.csv`` (one row per mutation:
killed / SURVIVED / error / stale / timeout, the seconds it took) and prints the table.
Exit code 0 when every mutant is killed, 1 otherwise (a survivor, a mutation whose
original text is no longer in its file, a test run that errors or times out), 2 when the
unmutated tests fail.

To add a mutation, append to MUTATIONS: the original text must occur exactly once in the
file (copy it with its indentation), and the tests should be the few that kill it.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BACKUP_SUFFIX = ".mutation-backup"


@dataclass(frozen=True)
class Mutation:
    name: str
    path: str  # relative to the repository root
    original: str  # exact text, occurring once in the file
    mutated: str
    tests: tuple[str, ...]  # pytest node ids expected to fail on the mutant
    why: str


PLANNER_CHECK = "schedsyn/planner/check.py"
PLANNER_CORE = "schedsyn/planner/core.py"

MUTATIONS: tuple[Mutation, ...] = (
    Mutation(
        "uncertainty-box-ignores-the-effect-fit",
        "schedsyn/replan.py",
        '    if m.effect != "none" and m.effect == e.effect:  # planned with the effect: '
        "its own fit",
        "    if False:",
        (
            "tests/test_replan.py::"
            "test_a_material_effect_is_kept_and_a_clean_log_keeps_the_base_model",
        ),
        "a rest planned with an effect gets the base fit's tau and dT0 errors for its box",
    ),
    Mutation(
        "uncertainty-reports-the-best-corner",
        "schedsyn/replan.py",
        "    worst, wt, wd = min(corners, key=lambda c: c[0].preference())",
        "    worst, wt, wd = max(corners, key=lambda c: c[0].preference())",
        (
            "tests/test_replan.py::"
            "test_the_run_is_checked_at_the_corners_of_the_identified_box_as_scipy_counts_it",
        ),
        "the uncertainty check reports the best corner of the box as its worst",
    ),
    Mutation(
        "uncertainty-dt0-not-varied",
        "schedsyn/replan.py",
        "        (predict_run(replace(request, model=replace(m, tau_s=t, dt0_c=d)), "
        "programme), t, d)",
        "        (predict_run(replace(request, model=replace(m, tau_s=t)), programme), t, d)",
        (
            "tests/test_replan.py::"
            "test_the_run_is_checked_at_the_corners_of_the_identified_box_as_scipy_counts_it",
        ),
        "the corners of the uncertainty box vary tau only",
    ),
    Mutation(
        "monitor-never-advises-a-replan",
        "schedsyn/monitor.py",
        "        if self.predicted.complete or self.remaining_min <= 0.0:",
        "        if True:",
        (
            "tests/test_monitor.py::"
            "test_a_run_predicted_short_says_how_to_re_plan_it_and_that_command_runs",
        ),
        "a run predicted short of its target gets no re-plan advice",
    ),
    Mutation(
        "monitor-replan-minute-past-the-log",
        "schedsyn/monitor.py",
        "        m = float(math.floor(self.elapsed_min + 1e-9))",
        "        m = float(math.ceil(self.elapsed_min + 1e-9))",
        (
            "tests/test_monitor.py::"
            "test_a_run_predicted_short_says_how_to_re_plan_it_and_that_command_runs",
        ),
        "the advised re-plan minute lies past the end of the log",
    ),
    Mutation(
        "graded-never-climbs",
        PLANNER_CORE,
        "        while k + 1 in fits and attempt(k + 1) is not None:",
        "        while False and k + 1 in fits and attempt(k + 1) is not None:",
        (
            "tests/test_graded_effort.py::"
            "test_the_graded_search_plans_few_counts_and_finds_the_most_levels",
        ),
        "the graded search keeps its first guess without trying one level more",
    ),
    Mutation(
        "graded-answers-one-level-fewer",
        PLANNER_CORE,
        "    return None if found is None else _Fewer(k, found, tuple(sorted(tried)))",
        "    return None if found is None else _Fewer(k - 1, tried.get(k - 1) or found, "
        "tuple(sorted(tried)))",
        (
            "tests/test_graded_effort.py::"
            "test_the_graded_search_plans_few_counts_and_finds_the_most_levels",
        ),
        "the graded answer is one level below the most a complete plan reached",
    ),
    Mutation(
        "sweep-memo-ignores-the-segment-limit",
        "schedsyn/planner/search.py",
        "key = (u_fixed.tobytes(), d, band, max_seg, slow)",
        "key = (u_fixed.tobytes(), d, band, slow)",
        ("tests/test_sweep_memo.py",),
        "a sweep searched within a longer limit is reused within a shorter one",
    ),
    Mutation(
        "sweep-memo-ignores-slow",
        "schedsyn/planner/search.py",
        "key = (u_fixed.tobytes(), d, band, max_seg, slow)",
        "key = (u_fixed.tobytes(), d, band, max_seg)",
        ("tests/test_sweep_memo.py",),
        "the slow retry gets the usual timings' failure back and never tries slow timings",
    ),
    Mutation(
        "sweep-memo-counts-no-work",
        "schedsyn/planner/search.py",
        "        count_work(hit[1])\n",
        "",
        ("tests/test_sweep_memo.py",),
        "a reused sweep counts no LP work: an effort limit would cut later than it did",
    ),
    Mutation(
        "robust-nominal-check-skipped",
        "schedsyn/planner/robust.py",
        "    if holds_on_box is not None and holds_on_box(margin):",
        "    if False and holds_on_box is not None and holds_on_box(margin):",
        (
            "tests/test_planner.py::test_a_nominal_plan_that_holds_on_the_box_spares_the_inner_searches",
        ),
        "the inner half and quarter are searched although the nominal plan holds on the box",
    ),
    Mutation(
        "robust-nominal-check-always-holds",
        "schedsyn/planner/robust.py",
        "    if holds_on_box is not None and holds_on_box(margin):",
        "    if holds_on_box is not None:",
        ("tests/test_planner.py::test_too_wide_a_robust_box_says_which_part_is_covered",),
        "a nominal plan that does not hold on the box cuts the ladder short",
    ),
    Mutation(
        "robust-nominal-check-refuses-a-cut",
        PLANNER_CORE,
        "                u = cut.u\n",
        "                return False\n",
        (
            "tests/test_planner.py::test_a_nominal_plan_that_holds_on_the_box_spares_the_inner_searches",
        ),
        "an over-long nominal plan cut at the limit is never checked on the box",
    ),
    Mutation(
        "bounds-proof-wrong-side",
        "schedsyn/planner/lp.py",
        "least, most = lo * up + hi * down, hi * up + lo * down",
        "least, most = hi * up + lo * down, lo * up + hi * down",
        (
            "tests/test_lp_bounds.py::"
            "test_the_bounds_prove_only_what_a_solver_also_finds_infeasible",
        ),
        "the rate-limit proof takes a row's largest value for its least: feasible probes "
        "are called infeasible",
    ),
    Mutation(
        "bounds-proof-ignores-free-columns",
        "schedsyn/planner/lp.py",
        "        over &= ~np.any(a[:, n_rates:] != 0.0, axis=1)",
        "        pass",
        (
            "tests/test_lp_bounds.py::"
            "test_the_bounds_prove_only_what_a_solver_also_finds_infeasible",
        ),
        "rows with free columns (margins, epigraph) are judged on the rates alone",
    ),
    Mutation(
        "effort-counts-cpu-time",
        PLANNER_CORE,
        "and lp_nonzeros_solved() - self.work_tic > self.effort_s * LP_NONZEROS_PER_EFFORT_S",
        "and time.process_time() - self.work_tic / 1e9 > self.effort_s",
        (
            "tests/test_graded_effort.py::test_the_effort_limit_counts_lp_work_not_time",
            "tests/test_graded_effort.py::"
            "test_the_same_request_gets_the_same_answer_on_a_slower_machine",
        ),
        "the effort limit counts CPU time (load-dependent) instead of LP work",
    ),
    Mutation(
        "fine-check-off",
        "schedsyn/planner/check.py",
        "    if np.any(wider.levels < rep.levels):",
        "    if np.any(wider.levels < rep.levels - 1):",
        (
            "tests/test_planner.py::"
            "test_a_level_pair_right_at_delta_is_counted_as_a_finer_sampling_counts_it",
        ),
        "the planner check's finer sampling never runs for levels right at delta apart",
    ),
    Mutation(
        "step-table-bias",
        "schedsyn/programme.py",
        "            want = round(float(tk_target[i + 1]), 1)",
        "            want = round(float(tk_target[i + 1]) + 0.3, 1)",
        (
            "tests/test_programme.py::test_rounding_is_to_the_nearest_tenth",
            "tests/test_programme.py::test_rounded_programme_is_typable_and_within_half_a_step",
        ),
        "+0.3 degC bias in the rounded (exported) step-table temperatures",
    ),
    Mutation(
        "step-csv-bias",
        "schedsyn/programme.py",
        '        frame["tk_end_c"] = frame["tk_end_c"].round(3)',
        '        frame["tk_end_c"] = (frame["tk_end_c"] + 0.3).round(3)',
        ("tests/test_programme.py::test_round_trip_is_identity",),
        "+0.3 degC bias in the end temperatures written to the CSV",
    ),
    Mutation(
        "bic-penalty",
        "schedsyn/discrepancy.py",
        "    score = n * math.log(max(sse, 1e-300) / n) + k * math.log(n)",
        "    score = n * math.log(max(sse, 1e-300) / n)",
        (
            "tests/test_discrepancy.py"
            "::test_bic_penalty_decides_against_an_extra_parameter_on_a_clean_log",
        ),
        "the BIC penalty k ln N removed from the diagnosis",
    ),
    Mutation(
        "device-max-looser",
        PLANNER_CHECK,
        "t_hi > limits.device_max_c + DEVICE_TOL_C",
        "t_hi > limits.device_max_c + 1.0",
        (
            "tests/test_planner.py"
            "::test_check_programme_catches_a_device_limit_grazed_by_half_a_degree",
        ),
        "check_programme lets the device pass its upper limit by up to 1 degC",
    ),
    Mutation(
        "device-min-looser",
        PLANNER_CHECK,
        "t_lo < limits.device_min_c - DEVICE_TOL_C",
        "t_lo < limits.device_min_c - 1.0",
        (
            "tests/test_planner.py"
            "::test_check_programme_catches_a_device_limit_grazed_by_half_a_degree",
        ),
        "check_programme lets the device pass its lower limit by up to 1 degC",
    ),
    Mutation(
        "delta-0.9",
        "schedsyn/coverage.py",
        "        if x - last >= delta_c_per_min - 1e-12:",
        "        if x - last >= 0.9 * delta_c_per_min - 1e-12:",
        (
            "tests/test_coverage.py::test_levels_exactly_delta_apart_count_and_closer_ones_do_not",
            "tests/test_coverage.py::test_distinct_levels_is_the_largest_separated_subset",
        ),
        "distinct levels counted 0.9 delta apart instead of delta",
    ),
    Mutation(
        "incomplete-plan",
        PLANNER_CORE,
        "    raw = Programme(np.full(u.size, float(spec.segment_min)), u, limits.start_c)",
        "    raw = Programme(np.full(u.size, float(spec.segment_min)), 0.5 * u, limits.start_c)",
        (
            "tests/test_campaign.py::test_campaign_writes_every_output",
            "tests/test_campaign.py::test_exported_table_gives_the_reported_coverage",
            "tests/test_cli_plan.py"
            "::test_plan_with_a_model_file_writes_outputs_and_its_coverage_survives_re_simulation",
        ),
        "the planner hands back half its planned rates: an honestly reported incomplete plan",
    ),
    Mutation(
        "box-sweep-tau",
        "schedsyn/sweep.py",
        "        FirstOrderLag(ThermalParams(tau_s=chunk.tau_s, dt0_c=0.0)),",
        "        FirstOrderLag(ThermalParams(tau_s=chunk.tau_s * 1.05, dt0_c=0.0)),",
        ("tests/test_planner.py::test_too_wide_a_robust_box_says_which_part_is_covered",),
        "the fixed-plan sweep (robust box check) simulates with tau 5 % too long",
    ),
    Mutation(
        "lag-foh-slope",
        "schedsyn/model.py",
        "    beta = 1.0 - tau_min * (1.0 - a) / h_min",
        "    beta = 1.0 - tau_min * (1.0 - a) / h_min * 0.999",
        ("tests/test_lag.py::test_first_order_hold_update_matches_solve_ivp",),
        "the first-order-hold step's ramp term 0.1 % off",
    ),
    Mutation(
        "lag-ramp",
        "schedsyn/model.py",
        "    return x + tau_min * np.expm1(-x / tau_min)",
        "    return x + tau_min * np.expm1(-x / tau_min) * (1.0 + 1e-6)",
        ("tests/test_lag.py::test_step_and_ramp_responses_match_the_matrix_exponential",),
        "the lag's unit-ramp response 1e-6 relative off",
    ),
    Mutation(
        "estimator-variance-sign",
        "schedsyn/estimate.py",
        "        return g, p11 / tau**2 - 2.0 * p12 / tau + p22",
        "        return g, p11 / tau**2 + 2.0 * p12 / tau + p22",
        ("tests/test_calibration.py::test_model_based_sigma_with_a_nearly_constant_correction",),
        "the sign of the cross term in the model-based estimator's gradient variance "
        "(var g = P11/tau^2 - 2 P12/tau + P22): the stated sigma several times too large",
    ),
    Mutation(
        "second-chance-always",
        "schedsyn/planner/search.py",
        "search.overrun.n_seg <= max_seg * (",
        "search.overrun.n_seg <= 99 * max_seg * (",
        (
            "tests/test_second_chance.py::"
            "test_second_chance_only_when_the_best_structure_nearly_fits",
        ),
        "the second chance runs on every failing search, however far off",
    ),
    Mutation(
        "second-chance-never",
        "schedsyn/planner/search.py",
        "    near = search.overrun is not None and",
        "    near = False and search.overrun is not None and",
        (
            "tests/test_second_chance.py::"
            "test_second_chance_only_when_the_best_structure_nearly_fits",
        ),
        "a near miss gets no second chance",
    ),
    Mutation(
        "guide-edge-ignored",
        "schedsyn/planner/guide.py",
        '        if edge == "speed":',
        '        if edge == "never":',
        (
            "tests/test_second_chance.py::"
            "test_profiles_costed_at_the_edge_speed_are_another_shape_within_the_same_limits",
        ),
        "the second chance's profiles are the first ones again",
    ),
    Mutation(
        "dual-coupling-sign",
        "schedsyn/planner/bound.py",
        "            coef[k] += lam[p]\n            coef[i] -= lam[p]",
        "            coef[k] -= lam[p]\n            coef[i] += lam[p]",
        (
            "tests/test_bound.py::"
            "test_the_levels_dual_lies_between_the_ranks_apart_and_the_coupled_optimum",
        ),
        "the levels' dual pushes the ranks together instead of apart",
    ),
    Mutation(
        "dual-pairs-off-by-one",
        "schedsyn/planner/bound.py",
        "pairs = [(k, k - 1 - surplus) for k in range(surplus + 1, n)]",
        "pairs = [(k, k - surplus) for k in range(surplus + 1, n)]",
        (
            "tests/test_bound.py::"
            "test_the_levels_dual_lies_between_the_ranks_apart_and_the_coupled_optimum",
        ),
        "the dual couples each rank with itself",
    ),
)


# --------------------------------------------------------------------------------------
# applying and restoring
# --------------------------------------------------------------------------------------
def _backup_path(path: Path) -> Path:
    return path.with_name(path.name + BACKUP_SUFFIX)


def restore_leftovers() -> list[Path]:
    """Restore files a killed earlier run left mutated (from their backups)."""
    restored = []
    for rel in sorted({m.path for m in MUTATIONS}):
        path = ROOT / rel
        backup = _backup_path(path)
        if backup.exists():
            stat = backup.stat()
            path.write_bytes(backup.read_bytes())
            os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
            backup.unlink()
            restored.append(path)
    return restored


class Applied:
    """Context manager: the file holds the mutant inside, the original bytes after."""

    def __init__(self, mutation: Mutation):
        self.path = ROOT / mutation.path
        self.mutation = mutation
        self.original_bytes = b""
        self.stat: os.stat_result | None = None

    def __enter__(self) -> Applied:
        self.original_bytes = self.path.read_bytes()
        self.stat = self.path.stat()
        text = self.original_bytes.decode("utf-8")
        backup = _backup_path(self.path)
        backup.write_bytes(self.original_bytes)
        os.utime(backup, ns=(self.stat.st_atime_ns, self.stat.st_mtime_ns))
        self.path.write_text(
            text.replace(self.mutation.original, self.mutation.mutated, 1), encoding="utf-8"
        )
        # a modification time no cached bytecode of this file can carry
        newer = max(time.time_ns(), self.stat.st_mtime_ns + 2_000_000_000)
        os.utime(self.path, ns=(newer, newer))
        return self

    def __exit__(self, *exc) -> None:
        assert self.stat is not None
        self.path.write_bytes(self.original_bytes)
        # the original time stamp: its cached bytecode is valid again
        os.utime(self.path, ns=(self.stat.st_atime_ns, self.stat.st_mtime_ns))
        _backup_path(self.path).unlink(missing_ok=True)


# --------------------------------------------------------------------------------------
# running tests
# --------------------------------------------------------------------------------------
def run_tests(tests: tuple[str, ...], timeout_s: float, stop_first: bool) -> tuple[str, float]:
    """Run pytest on ``tests``: ``("passed" | "failed" | "error" | "timeout", seconds)``."""
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--no-header"]
    if stop_first:
        cmd.append("-x")
    # the mutant's bytecode is never cached (the restored file must not meet it later)
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    tic = time.perf_counter()
    proc = subprocess.Popen(
        [*cmd, *tests],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # its own process group: killed as a whole
    )
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return "timeout", time.perf_counter() - tic
    except BaseException:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    seconds = time.perf_counter() - tic
    if proc.returncode == 0:
        return "passed", seconds
    if proc.returncode == 1:
        return "failed", seconds
    tail = "\n".join(out.strip().splitlines()[-15:])
    print(f"pytest exit code {proc.returncode}:\n{tail}", file=sys.stderr)
    return "error", seconds


def check_mutation(m: Mutation, timeout_s: float) -> dict:
    path = ROOT / m.path
    row = {"mutation": m.name, "file": m.path, "why": m.why, "tests": " ".join(m.tests)}
    count = path.read_text(encoding="utf-8").count(m.original) if path.is_file() else 0
    if count != 1:
        return row | {"result": "stale", "seconds": 0.0, "note": f"original text found {count}x"}
    with Applied(m):
        outcome, seconds = run_tests(m.tests, timeout_s, stop_first=True)
    result = {"failed": "killed", "passed": "SURVIVED"}.get(outcome, outcome)
    return row | {"result": result, "seconds": round(seconds, 1), "note": ""}


def table(rows: list[dict]) -> str:
    lines = [
        "| mutation | file | result | s | what it plants | killed by |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        tests = ", ".join(f"`{t.split('::')[-1]}`" for t in r["tests"].split())
        lines.append(
            f"| {r['mutation']} | `{r['file']}` | **{r['result']}** {r['note']} | "
            f"{r['seconds']:g} | {r['why']} | {tests} |"
        )
    return "\n".join(lines)


def _raise_interrupt(signum, frame):  # SIGTERM behaves like Ctrl-C: restore, then stop
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutations")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--timeout", type=float, default=900.0, help="per test run, s")
    ap.add_argument(
        "--no-baseline", action="store_true", help="skip running the tests unmutated first"
    )
    ap.add_argument("--out", default="out/mutation_check", help="output directory")
    args = ap.parse_args(argv)
    if args.list:
        for m in MUTATIONS:
            print(f"{m.name:20s} {m.path:26s} {m.why}")
        return 0
    chosen = list(MUTATIONS)
    if args.only:
        unknown = sorted(set(args.only) - {m.name for m in MUTATIONS})
        if unknown:
            ap.error(f"unknown mutation(s) {unknown}; see --list")
        chosen = [m for m in MUTATIONS if m.name in args.only]
    # Ctrl-C and SIGTERM stop the run with every file restored (also when started in the
    # background, where a shell leaves SIGINT ignored)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _raise_interrupt)
    for path in restore_leftovers():
        print(f"restored {path} from an interrupted earlier run", file=sys.stderr)

    if not args.no_baseline:
        tests = tuple(dict.fromkeys(t for m in chosen for t in m.tests))
        print(f"baseline: {len(tests)} test selections on the unmutated code ...", file=sys.stderr)
        outcome, seconds = run_tests(tests, args.timeout, stop_first=False)
        print(f"baseline: {outcome} in {seconds:.0f} s", file=sys.stderr)
        if outcome != "passed":
            print("the tests fail without any mutation: fix them first", file=sys.stderr)
            return 2
    rows: list[dict] = []
    try:
        for m in chosen:
            print(f"{m.name}: {m.why} ...", file=sys.stderr, flush=True)
            rows.append(check_mutation(m, args.timeout))
            print(f"  {rows[-1]['result']} ({rows[-1]['seconds']} s)", file=sys.stderr)
    except KeyboardInterrupt:
        print("interrupted: every file is restored", file=sys.stderr)
        print(table(rows))
        return 130

    import pandas as pd

    from schedsyn.io import write_frame_atomic, write_text_atomic

    text = table(rows)
    out = ROOT / args.out
    write_text_atomic(out / "mutation_check.md", text + "\n")
    write_frame_atomic(out / "mutation_check.csv", pd.DataFrame(rows))
    print(text)
    bad = [r["mutation"] for r in rows if r["result"] != "killed"]
    print(
        f"\n{len(rows) - len(bad)} of {len(rows)} mutants killed"
        + (f"; NOT killed: {', '.join(bad)}" if bad else "")
        + f"; table in {out / 'mutation_check.md'}"
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
