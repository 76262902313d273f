"""Progress on long work (issue 16, item 4): tqdm on a terminal, timestamped lines in a log,
nothing with --quiet."""

from __future__ import annotations

import io
import pickle
import re

from schedsyn.cli import main
from schedsyn.progress import Progress

STAMP = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d ")
STEPS = "data/baseline_exp1_steps.csv"


def test_log_form_is_timestamped_lines():
    buf = io.StringIO()
    p = Progress(stream=buf, tty=False)
    p("W1 [  1.0 s] planning")
    p("second\n")
    lines = buf.getvalue().splitlines()
    assert len(lines) == 2 and all(STAMP.match(ln) for ln in lines)
    assert lines[0].endswith("W1 [  1.0 s] planning") and lines[1].endswith("second")


def test_terminal_form_clears_the_bar_line_and_has_no_timestamp():
    buf = io.StringIO()
    Progress(stream=buf, tty=True)("hello")
    assert buf.getvalue() == "\r\x1b[2Khello\n"


def test_quiet_writes_nothing():
    buf = io.StringIO()
    p = Progress(enabled=False, stream=buf, tty=False)
    p("x")
    with p.bar(5, "items") as bar:
        for _ in range(5):
            bar.update()
    assert buf.getvalue() == ""


def test_counted_work_in_a_log_is_a_line_per_tenth():
    buf = io.StringIO()
    with Progress(stream=buf, tty=False).bar(20, "items") as bar:
        for _ in range(20):
            bar.update()
    lines = buf.getvalue().splitlines()
    assert len(lines) == 10 and all(STAMP.match(ln) for ln in lines)
    assert [int(re.search(r"items: (\d+)/20 done", ln).group(1)) for ln in lines] == list(
        range(2, 21, 2)
    )


def test_counted_work_on_a_terminal_is_a_tqdm_bar():
    buf = io.StringIO()
    with Progress(stream=buf, tty=True).bar(3, "items") as bar:
        for _ in range(3):
            bar.update()
    text = buf.getvalue()
    assert "items" in text and "/3 [" in text and "\r" in text and not STAMP.search(text)


def test_progress_travels_to_worker_processes():
    p = pickle.loads(pickle.dumps(Progress(enabled=False)))
    assert isinstance(p, Progress) and p.enabled is False


def test_cli_quiet_silences_progress_and_default_shows_it(tmp_path, capsys):
    common = ["sweep", STEPS, "--region", "-50", "-30", "--tau-s", "2000:2800:5"]
    common += ["--dt0-c", "0:6:3", "--workers", "1"]
    assert main([*common, "--out", str(tmp_path / "a"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert main([*common, "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err and all(STAMP.match(ln) for ln in err), err  # stderr is not a terminal here
    assert err[-1].endswith("5/5 done (0 s)") or re.search(r"5/5 done \(\d+ s\)$", err[-1])


def test_a_search_silent_for_long_says_where_it_is(monkeypatch):
    """A search that places no sweep for HEARTBEAT_S says what it is scanning (a robust
    box's first sweep was searched 25 min without a line); the beat goes through the
    same progress and resets its clock, and only speaks when the last line is old."""
    from schedsyn.planner import search

    now = [0.0]
    lines: list[str] = []
    heart = search.Heartbeat(lines.append, lambda: now[0])
    heart.beat(lambda: "early")
    now[0] = search.HEARTBEAT_S - 0.1
    heart.beat(lambda: "still early")
    assert lines == []
    now[0] = search.HEARTBEAT_S
    heart.beat(lambda: "late")
    heart.beat(lambda: "again")  # the clock was reset by the line just written
    heart("sweep placed")
    now[0] += search.HEARTBEAT_S - 0.1
    heart.beat(lambda: "too soon after a line")
    assert lines == ["late", "sweep placed"]


def test_the_heartbeat_names_the_design_and_the_scan(monkeypatch):
    """Through the planner, every scan step beats (HEARTBEAT_S 0): the line names the
    band design, the first direction and how far the turnaround scan has got."""
    from schedsyn import Limits, ThermalParams
    from schedsyn.planner import ExperimentSpec, plan_experiment, search

    monkeypatch.setattr(search, "HEARTBEAT_S", 0.0)
    lines: list[str] = []
    spec = ExperimentSpec("H", -4.0, 0.0, -6.0, 2.0, levels_required=2)
    plan_experiment(spec, ThermalParams(), Limits(duration_max_min=200.0), progress=lines.append)
    beats = [ln for ln in lines if ln.startswith("still searching (")]
    assert beats, lines
    assert re.search(
        r"still searching \((guided|classic) bands, (cooling|heating) first, \d+ sweeps.*\): "
        r"a (cooling|heating) sweep in band \d+ after minute [\d.]+, turnaround [\d.]+ of "
        r"[\d.]+ min scanned; \d+ LPs so far",
        beats[0],
    ), beats[0]
