"""Exit codes, one-line faults, checks before work, all-or-nothing outputs (issue 13, 3-4).

Exit codes: 0 complete, 1 plan incomplete, 2 bad input, 3 environment fault, 4 a bug.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from schedsyn.cli import main
from schedsyn.errors import EnvironmentFaultError
from schedsyn.io import INCOMPLETE_MARKER, MANIFEST, OutputDir

STEPS = "data/baseline_exp1_steps.csv"
REPO = Path(__file__).resolve().parents[1]


def _one_line(err: str) -> str:
    err = err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


def _unwritable(tmp_path: Path) -> Path:
    """A folder that cannot be written: read-only for a normal user; under root (where
    permissions do not stop writes) a path below a regular file."""
    if hasattr(os, "geteuid") and os.geteuid() != 0:
        d = tmp_path / "readonly"
        d.mkdir()
        d.chmod(0o500)
        return d / "out"
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    return blocker / "out"


# ---------------------------------------------------------------------------------------
# exit code 3: the environment
# ---------------------------------------------------------------------------------------
def test_an_unwritable_output_folder_is_one_line_and_exit_3(tmp_path, capsys):
    out = _unwritable(tmp_path)
    rc = main(["simulate", STEPS, "--region", "-50", "-30", "--out", str(out)])
    err = _one_line(capsys.readouterr().err)
    assert rc == 3
    assert err.startswith("schedsyn simulate: fault: cannot write the outputs to")
    assert str(out) in err


def test_campaign_checks_its_outputs_before_planning(tmp_path, capsys, monkeypatch):
    """Unwritable folder (3) or an output that is an input (2): refused in moments."""
    import schedsyn.campaign

    def planning(*args, **kwargs):
        raise AssertionError("planning started before the outputs were checked")

    monkeypatch.setattr(schedsyn.campaign, "plan_campaign", planning)
    assert main(["campaign", "--out", str(_unwritable(tmp_path)), "--quiet"]) == 3
    assert "fault: cannot write" in _one_line(capsys.readouterr().err)

    # a config whose baseline step table is one of the campaign's outputs
    out = tmp_path / "out"
    (out / "S").mkdir(parents=True)
    shutil.copy(STEPS, out / "S" / "steps.csv")
    before = (out / "S" / "steps.csv").read_bytes()
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        textwrap.dedent(
            f"""
            [[experiment]]
            name = "S"
            working_lo_c = -10
            working_hi_c = 0
            approx_lo_c = -20
            approx_hi_c = 10
            baseline_steps = "{(out / "S" / "steps.csv").as_posix()}"
            """
        )
    )
    assert main(["campaign", str(cfg), "--out", str(out), "--quiet"]) == 2
    err = _one_line(capsys.readouterr().err)
    assert "refusing to overwrite the input" in err and "steps.csv" in err
    assert (out / "S" / "steps.csv").read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["S"]  # no staging folder left


def test_disk_full_midway_is_exit_3_and_writes_nothing(tmp_path, capsys, monkeypatch):
    calls = []
    original = pd.DataFrame.to_csv

    def full(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # the second table: trajectory.csv is already staged
            raise OSError(errno.ENOSPC, "No space left on device", str(args[0]))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", full)
    out = tmp_path / "o"
    rc = main(["simulate", STEPS, "--region", "-50", "-30", "--out", str(out)])
    err = _one_line(capsys.readouterr().err)
    assert rc == 3 and "No space left on device" in err
    assert not out.exists()  # all or nothing
    assert list(tmp_path.iterdir()) == []  # and no staging folder


def test_a_killed_worker_is_an_environment_fault(tmp_path, capsys, monkeypatch):
    from schedsyn.sweep import run_map

    with pytest.raises(EnvironmentFaultError, match="worker process"):
        run_map(os._exit, [1, 1], "local", workers=2, progress=False)

    import schedsyn.cli.sweep as cli_sweep

    def broken(*args, **kwargs):
        raise EnvironmentFaultError("a worker process of the local pool died")

    monkeypatch.setattr(cli_sweep, "sweep_fixed", broken)
    rc = main(["sweep", STEPS, "--region", "-50", "-30", "--out", str(tmp_path / "s"), "--quiet"])
    assert rc == 3
    assert _one_line(capsys.readouterr().err).startswith("schedsyn sweep: fault:")
    assert not (tmp_path / "s").exists()


def test_a_bug_is_one_line_and_exit_4(tmp_path, capsys, monkeypatch):
    import schedsyn.cli.simulate as cli_simulate

    def bug(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(cli_simulate, "trajectory_coverage", bug)
    monkeypatch.delenv("SCHEDSYN_DEBUG", raising=False)
    rc = main(["simulate", STEPS, "--region", "-50", "-30", "--out", str(tmp_path / "o")])
    err = _one_line(capsys.readouterr().err)
    assert rc == 4 and "internal error: ZeroDivisionError" in err and "SCHEDSYN_DEBUG" in err
    monkeypatch.setenv("SCHEDSYN_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        main(["simulate", STEPS, "--region", "-50", "-30", "--out", str(tmp_path / "o")])


# ---------------------------------------------------------------------------------------
# all or nothing
# ---------------------------------------------------------------------------------------
def _write(out: OutputDir, files: dict[str, str]) -> None:
    for name, text in files.items():
        out.path(name).write_text(text)


def test_output_dir_commits_all_at_once_and_replaces_an_earlier_run(tmp_path):
    target = tmp_path / "out"
    first = OutputDir(target, command="first")
    first.check(["a.csv", "W1/x.png", "W2/x.png"])
    _write(first, {"a.csv": "1", "W1/x.png": "1", "W2/x.png": "1"})
    assert not target.exists()  # nothing visible before the commit
    first.commit()
    listed = {f["path"] for f in json.loads((target / MANIFEST).read_text())["files"]}
    assert listed == {"a.csv", "W1/x.png", "W2/x.png"}
    (target / "notes.txt").write_text("mine")  # a user's file: never touched
    second = OutputDir(target, command="second")
    _write(second, {"a.csv": "2", "W1/x.png": "2"})
    second.commit()
    assert (target / "a.csv").read_text() == "2" and (target / "W1/x.png").read_text() == "2"
    assert not (target / "W2").exists()  # stale output of the first run: removed
    assert (target / "notes.txt").read_text() == "mine"
    assert json.loads((target / MANIFEST).read_text())["command"] == "second"
    assert not (target / INCOMPLETE_MARKER).exists()
    assert [p.name for p in target.iterdir() if p.name.startswith(".")] == []


def test_stale_files_that_changed_or_are_inputs_are_kept(tmp_path):
    target = tmp_path / "out"
    first = OutputDir(target)
    _write(first, {"edited.csv": "1", "input.csv": "1", "plain.csv": "1"})
    first.commit()
    time.sleep(0.01)
    (target / "edited.csv").write_text("edited by hand")
    second = OutputDir(target, inputs=[target / "input.csv"])
    _write(second, {"new.csv": "2"})
    second.commit()
    assert (target / "edited.csv").read_text() == "edited by hand"
    assert (target / "input.csv").exists()
    assert not (target / "plain.csv").exists()
    assert sorted(p.name for p in second.kept_stale) == ["edited.csv", "input.csv"]


def test_another_commands_outputs_in_the_folder_are_never_removed(tmp_path):
    """Red team: `schedsyn compare LOG runB/steps.csv --out runB` after `schedsyn plan
    --out runB` removed plan.json and the plots as stale (`estimate --out` even steps.csv):
    only an earlier run of the same command has stale files; another's are kept, and
    still listed, so a rerun of that command replaces them as before."""
    target = tmp_path / "runB"
    plan = OutputDir(target, command=f"schedsyn plan --working -50 -30 --out {target}")
    _write(plan, {"steps.csv": "s", "plan.json": "p", "phase.png": "1", "W/old.png": "1"})
    plan.commit()
    cmp = OutputDir(target, command=f"schedsyn compare log.csv {target}/steps.csv --out x")
    _write(cmp, {"compare.csv": "c", "summary.json": "j"})
    cmp.commit()
    names = sorted(str(p.relative_to(target)) for p in target.rglob("*") if p.is_file())
    kept = ["W/old.png", "compare.csv", "phase.png", "plan.json", "steps.csv", "summary.json"]
    assert names == sorted([MANIFEST, *kept])
    listed = {f["path"]: f["by"] for f in json.loads((target / MANIFEST).read_text())["files"]}
    assert listed["plan.json"] == "plan" and listed["compare.csv"] == "compare"
    # the plan again, without W/old.png: its own stale file goes, compare's stay
    again = OutputDir(target, command=f"schedsyn --quiet plan --out {target}")
    _write(again, {"steps.csv": "s2", "plan.json": "p2", "phase.png": "2"})
    again.commit()
    assert not (target / "W").exists()
    assert (target / "compare.csv").read_text() == "c"
    assert (target / "steps.csv").read_text() == "s2"


def test_discard_leaves_the_target_as_it_was(tmp_path):
    target = tmp_path / "deep" / "out"
    out = OutputDir(target)
    out.check(["a.csv"])
    _write(out, {"a.csv": "x"})
    out.discard()
    assert not (tmp_path / "deep").exists()  # even the folders made for it


_KILL_DURING_COMMIT = """
import os, signal, sys
from pathlib import Path
import schedsyn.io as io

target = Path(sys.argv[1])
moves = [0]
real_replace = os.replace

def replace(src, dst):
    if "staging" in str(src):
        moves[0] += 1
        if moves[0] == 3:  # killed after two files of the new run are in place
            os.kill(os.getpid(), signal.SIGKILL)
    return real_replace(src, dst)

io.os.replace = replace
out = io.OutputDir(target, command="schedsyn campaign --out " + str(target))
for name in ("summary.csv", "W1/steps.csv", "W1/phase.png", "W2/steps.csv"):
    out.path(name).write_text("new")
out.commit()
"""


def test_sigkill_while_moving_outputs_in_leaves_them_clearly_marked(tmp_path):
    target = tmp_path / "out"
    old = OutputDir(target, command=f"schedsyn campaign --out {target}")
    _write(old, {n: "old" for n in ("summary.csv", "W1/steps.csv", "W1/phase.png", "W3/a")})
    old.commit()
    script = tmp_path / "kill.py"
    script.write_text(_KILL_DURING_COMMIT)
    res = subprocess.run([sys.executable, str(script), str(target)], cwd=REPO, timeout=120)
    assert res.returncode == -signal.SIGKILL
    texts = {
        str(p.relative_to(target)): p.read_text()
        for p in target.rglob("*")
        if p.is_file() and not p.name.startswith(".")
    }
    assert "new" in texts.values() and "old" in texts.values()  # a mix ...
    marker = texts[INCOMPLETE_MARKER]  # ... that says so
    assert "may mix" in marker and "schedsyn campaign --out" in marker
    # the next complete run clears the mark and the leftovers
    again = OutputDir(target, command=f"schedsyn campaign --out {target}")
    _write(again, {"summary.csv": "newer"})
    again.commit()
    assert not (target / INCOMPLETE_MARKER).exists()
    assert sorted(p.name for p in target.iterdir()) == [MANIFEST, "summary.csv"]


# ---------------------------------------------------------------------------------------
# a real `schedsyn campaign` killed while planning: no workers left, outputs untouched
# ---------------------------------------------------------------------------------------
def _processes() -> dict[int, tuple[int, str]]:
    """pid -> (ppid, state) of every process (Linux /proc)."""
    procs = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        procs[int(d.name)] = (int(fields[1]), fields[0])
    return procs


def _descendants(pid: int) -> set[int]:
    procs = _processes()
    found, frontier = set(), {pid}
    while frontier:
        children = {p for p, (pp, _) in procs.items() if pp in frontier} - found
        found |= children
        frontier = children
    return found


def _running(pids: set[int]) -> set[int]:
    procs = _processes()
    return {p for p in pids if p in procs and procs[p][1] not in ("Z", "X")}


TWO_EXPERIMENTS = """
[settings]
levels_required = 4
[[experiment]]
name = "A"
working_lo_c = -10
working_hi_c = 0
approx_lo_c = -20
approx_hi_c = 10
[[experiment]]
name = "B"
working_lo_c = 0
working_hi_c = 10
approx_lo_c = -10
approx_hi_c = 20
"""


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_sigkill_of_a_campaign_leaves_no_worker_and_the_outputs_untouched(tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_EXPERIMENTS)
    out = tmp_path / "out"
    earlier = OutputDir(out)  # an earlier run's outputs
    _write(earlier, {"summary.csv": "earlier", "A/steps.csv": "earlier", "C/steps.csv": "x"})
    earlier.commit()

    def files():
        return {
            p: p.read_bytes()
            for p in out.rglob("*")
            if p.is_file() and "schedsyn-staging" not in str(p)
        }

    before = files()
    schedsyn = Path(sys.executable).with_name("schedsyn")
    proc = subprocess.Popen(
        [str(schedsyn), "campaign", str(cfg), "--out", str(out), "--workers", "2"],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        cwd=tmp_path,
    )
    started: set[str] = set()
    workers: set[int] = set()
    deadline = time.monotonic() + 120
    try:
        while started != {"A", "B"}:  # both experiments are being planned by workers
            line = proc.stderr.readline()
            assert line and time.monotonic() < deadline, "the campaign never started"
            for name in ("A", "B"):
                if f" {name} [" in line:
                    started.add(name)
        workers = _descendants(proc.pid)
        assert len(_running(workers)) >= 2, workers
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        deadline = time.monotonic() + 15
        while _running(workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _running(workers) == set(), "worker processes outlived the campaign"
    finally:  # never leave a process behind, even when the test fails
        for p in _running(workers | _descendants(proc.pid)):
            os.kill(p, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
        proc.stderr.close()
    assert files() == before  # killed before its commit: the earlier run is intact
    staged = [p for p in tmp_path.iterdir() if "schedsyn-staging" in p.name]
    staged += [p for p in out.iterdir() if "schedsyn-staging" in p.name]
    assert staged  # what the killed run had staged ...
    nxt = OutputDir(out)
    nxt.check()  # ... the next run removes
    nxt.discard()
    assert all(not p.exists() for p in staged)


def test_staging_left_by_a_dead_run_is_removed_beside_and_inside(tmp_path):
    dead = subprocess.Popen(["true"])  # a pid that has exited
    dead.wait()
    target = tmp_path / "out"
    beside = tmp_path / f".out.schedsyn-staging-{dead.pid}-abc"
    other = tmp_path / f".other.schedsyn-staging-{dead.pid}-abc"  # another target's
    beside.mkdir()
    other.mkdir()
    target.mkdir()
    inside = target / f".out.schedsyn-staging-{dead.pid}-def"
    inside.mkdir()
    alive = target / f".out.schedsyn-staging-{os.getpid()}-ghi"  # a live run's
    alive.mkdir()
    out = OutputDir(target)
    out.check()
    out.discard()
    assert not beside.exists() and not inside.exists()
    assert other.exists() and alive.exists()


def _deaf_to_sigterm() -> None:  # a pool worker the executor's terminate() misses
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    time.sleep(120)


def test_a_broken_pools_straggler_is_killed_not_waited_for(monkeypatch):
    """CI hung an hour (2026-12-03) in the executor's clean-up of a pool whose worker had
    died: it joins the other workers, and one its terminate() had missed was still
    reading its call queue. The pool is now shut down by killing its workers until the
    executor's manager thread is done; a worker deaf to SIGTERM stands in for the one
    missed, the manager thread for the executor's join."""
    import multiprocessing
    import threading
    import types

    from schedsyn import sweep

    monkeypatch.setattr(sweep, "BROKEN_POOL_WAIT_S", 20.0)
    worker = multiprocessing.get_context("fork").Process(target=_deaf_to_sigterm)
    worker.start()
    time.sleep(0.3)
    worker.terminate()  # missed
    manager = threading.Thread(target=worker.join, daemon=True)
    manager.start()
    pool = types.SimpleNamespace(
        _processes={worker.pid: worker},
        _executor_manager_thread=manager,
        shutdown=lambda **kw: None,
    )
    tic = time.monotonic()
    sweep._stop_broken_pool(pool)
    assert not worker.is_alive() and not manager.is_alive()
    assert time.monotonic() - tic < 10.0


def _sleep_or_sigint(seconds: float) -> bool:
    """A pool task: whether Ctrl-C is ignored in the worker, after sleeping ``seconds``."""
    time.sleep(seconds)
    return signal.getsignal(signal.SIGINT) == signal.SIG_IGN


class _InterruptAfterFirst:
    """A progress bar whose first update raises KeyboardInterrupt (Ctrl-C in the owner)."""

    def __init__(self) -> None:
        self.n = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def update(self, k: int) -> None:
        self.n += k
        raise KeyboardInterrupt


def test_ctrl_c_stops_the_local_pool_at_once_and_workers_leave_it_to_the_owner(monkeypatch):
    """Red team: after Ctrl-C the campaign waited up to 17 s for the experiments under way,
    once for ever (a worker that took the KeyboardInterrupt inside the call queue's lock),
    and a worker printed a traceback. The workers ignore SIGINT (the owner handles it),
    and an interrupted pool's workers are killed, not waited for."""
    from schedsyn import sweep

    assert sweep.run_map(_sleep_or_sigint, [0.0, 0.0], workers=2, progress=False) == [True] * 2
    monkeypatch.setattr(sweep, "_progress_bar", lambda *a, **k: _InterruptAfterFirst())
    tic = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        sweep.run_map(_sleep_or_sigint, [0.0, 60.0, 60.0], workers=2, progress=False)
    assert time.monotonic() - tic < 30.0  # not the 60 s the others would have taken


def test_an_unwritable_output_is_named_by_its_own_path(tmp_path):
    """Red team: `export --out /sys/x.csv` said "fault: Permission denied:
    /sys/.x.csv.f68zin27.csv", a temporary name, with no hint. The output's own path and
    what to do instead."""
    from schedsyn.errors import EnvironmentFaultError
    from schedsyn.io import write_text_atomic

    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    target = blocker / "out.csv"  # its folder is a file: no folder can be made there
    with pytest.raises(EnvironmentFaultError) as err:
        write_text_atomic(target, "t")
    text = str(err.value)
    assert f"cannot write {target} (" in text and "choose another output path" in text
    assert ".out.csv." not in text  # no temporary name
