"""Sensitivity sweeps over the model parameters ``tau`` and ``dT0``, and the backends that run them.

Two kinds of sweep over a grid of ``(tau_s, dt0_c)`` points:

* **fixed plan** (:func:`sweep_fixed`, :func:`verify_box`): how the coverage of one chamber
  programme degrades when the device's ``tau`` and ``dT0`` are not the planned ones. The
  metric is :func:`schedsyn.coverage.coverage_report`, unchanged.
* **re-plan** (:func:`sweep_replan`): plan again at every point with a caller's ``plan_fn``
  (how much the optimum itself moves).

Vectorisation of the fixed-plan sweep. The model is affine in the rates (see
:mod:`schedsyn.model`)::

    T = A_T(tau) u + b_T(tau, dT0),   g = A_g(tau) u + b_g(tau, dT0)

and ``dT0`` enters only through the free response (``T_free`` depends on ``Tk0 + dT0``
and ``T0``)::

    b_T = e T0 + (1 - e)(Tk0 + dT0),   b_g = e (Tk0 + dT0 - T0) / tau,   e = exp(-t/tau)

so for one ``tau`` a single :func:`~schedsyn.model.affine_response` and one product
``A u`` serve every ``dT0``; each ``dT0`` then costs one elementwise free response and the
coverage metric. The grid is chunked by ``tau`` value for the parallel backends.

An augmented model (``model=``, a :class:`~schedsyn.effects.ModelSpec` from ``schedsyn
diagnose``: a chamber lag, a second time constant, a rate limit, ...) is swept the same
way over its base ``tau`` and ``dT0``, its effect held at its fitted strength; each point
is then :meth:`ModelSpec.predict <schedsyn.effects.ModelSpec.predict>` (exact for linear
effects, on a fine grid for the others), which the single-product shortcut above does not
cover.

Backends (:func:`run_map`): ``"serial"`` (in this process), ``"local"`` (a process pool on
the local cores) or a Dask scheduler address such as ``"tcp://HOST:PORT"`` (needs the
``dask`` extra). Every backend returns the same results in the same order.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from .coverage import coverage_report
from .errors import EnvironmentFaultError, InfeasiblePlanError, ParameterError, SchedsynError
from .grid import BinGrid
from .model import FirstOrderLag, affine_response
from .params import DT0_ABS_MAX_C, TAU_MAX_S, ThermalParams
from .programme import Programme
from .progress import Progress
from .simulate import dense_times

#: The issue's minimum density of a verification sweep over a box (tau x dT0 points).
MIN_VERIFY_N_TAU = 9
MIN_VERIFY_N_DT0 = 7

__all__ = [
    "ReplanResult",
    "SweepResult",
    "default_grid",
    "parse_grid",
    "parse_range",
    "run_map",
    "sweep_fixed",
    "sweep_replan",
    "verify_box",
]


# ---------------------------------------------------------------------------------------
# grid strings
# ---------------------------------------------------------------------------------------
def _number(text: str, what: str, name: str, spec: str, example: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ParameterError(
            f"{name}: {what} {text.strip()!r} in {spec!r} is not a number (expected {example})"
        ) from None
    if not math.isfinite(v):
        raise ParameterError(f"{name}: {what} in {spec!r} must be finite (expected {example})")
    return v


def parse_grid(spec: str, name: str = "grid", unit: str = "") -> np.ndarray:
    """Parse ``"START:STOP:N"`` (N evenly spaced values, both ends included) or ``"VALUE"``.

    Examples: ``"1800:3000:13"`` gives 1800, 1900, ..., 3000; ``"2400"`` gives one value.

    Raises
    ------
    ParameterError
        One line naming ``name``, what is wrong and the expected form.
    """
    example = f"START:STOP:N such as 1800:3000:13{' ' + unit if unit else ''}, or one value"
    text = str(spec).strip()
    parts = text.split(":")
    if len(parts) == 1:
        return np.array([_number(parts[0], "value", name, text, example)])
    if len(parts) != 3:
        raise ParameterError(
            f"{name}: {text!r} has {len(parts)} ':'-separated parts; expected {example}"
        )
    start = _number(parts[0], "START", name, text, example)
    stop = _number(parts[1], "STOP", name, text, example)
    try:
        n = int(parts[2])
    except ValueError:
        raise ParameterError(
            f"{name}: N {parts[2].strip()!r} in {text!r} is not a whole number of points "
            f"(expected {example})"
        ) from None
    if n < 1:
        raise ParameterError(f"{name}: N in {text!r} must be >= 1 point, got {n}")
    if n > 10_000:
        raise ParameterError(f"{name}: N in {text!r} is {n}; use at most 10000 points per axis")
    if n == 1:
        if start != stop:
            raise ParameterError(
                f"{name}: one point (N = 1) needs START = STOP, got {text!r}; give one value "
                "instead or N >= 2"
            )
        return np.array([start])
    if not start < stop:
        raise ParameterError(f"{name}: START must be < STOP in {text!r}")
    return np.linspace(start, stop, n)


def parse_range(spec: str, name: str = "range") -> tuple[float, float]:
    """Parse ``"LO:HI"`` (``LO <= HI``) into a pair of floats, e.g. ``"2000:2800"``."""
    example = "LO:HI such as 2000:2800"
    text = str(spec).strip()
    parts = text.split(":")
    if len(parts) != 2:
        raise ParameterError(f"{name}: {text!r} is not {example}")
    lo = _number(parts[0], "LO", name, text, example)
    hi = _number(parts[1], "HI", name, text, example)
    if lo > hi:
        raise ParameterError(f"{name}: LO must be <= HI in {text!r}")
    return lo, hi


#: The default sweep grid around a nominal point: tau within this share of it either side,
#: dT0 within ``DEFAULT_DT0_SPREAD_C``, ``DEFAULT_GRID_N`` values each. Around schedsyn's
#: default nominal (2400 s, 3 degC) that is the grid the issue asked for, 1800 .. 3000 s
#: x 0 .. 6 degC, 13 x 13.
DEFAULT_TAU_SPREAD = 0.25
DEFAULT_DT0_SPREAD_C = 3.0
DEFAULT_GRID_N = 13


def default_grid(
    nominal: ThermalParams,
    tau_s_range: tuple[float, float] | None = None,
    dt0_c_range: tuple[float, float] | None = None,
    n: int = DEFAULT_GRID_N,
) -> tuple[np.ndarray, np.ndarray]:
    """``(tau_s_values, dt0_c_values)``: the default grid of a sweep around ``nominal``.

    ``n`` evenly spaced values (ends included) of tau from ``(1 - DEFAULT_TAU_SPREAD)``
    to ``(1 + DEFAULT_TAU_SPREAD)`` times the nominal tau and of dT0 within
    ``DEFAULT_DT0_SPREAD_C`` of the nominal dT0, each axis widened to take in
    ``tau_s_range`` / ``dt0_c_range`` when given (a robust plan's box), within the
    limits of :class:`~schedsyn.params.ThermalParams`. Around 2400 s, 3 degC it is
    1800 .. 3000 s x 0 .. 6 degC.
    """
    if int(n) != n or n < 2:
        raise ParameterError(f"a default grid needs n >= 2 values per axis, got {n!r}")
    tau, dt0 = nominal.tau_s, nominal.dt0_c
    t_lo, t_hi = (1.0 - DEFAULT_TAU_SPREAD) * tau, (1.0 + DEFAULT_TAU_SPREAD) * tau
    d_lo, d_hi = dt0 - DEFAULT_DT0_SPREAD_C, dt0 + DEFAULT_DT0_SPREAD_C
    if tau_s_range is not None:
        t_lo, t_hi = min(t_lo, float(tau_s_range[0])), max(t_hi, float(tau_s_range[1]))
    if dt0_c_range is not None:
        d_lo, d_hi = min(d_lo, float(dt0_c_range[0])), max(d_hi, float(dt0_c_range[1]))
    t_hi = min(t_hi, TAU_MAX_S)
    d_lo, d_hi = max(d_lo, -DT0_ABS_MAX_C), min(d_hi, DT0_ABS_MAX_C)
    return np.linspace(t_lo, t_hi, int(n)), np.linspace(d_lo, d_hi, int(n))


def _axis(values, name: str) -> np.ndarray:
    v = np.atleast_1d(np.asarray(values, dtype=float))
    if v.ndim != 1 or v.size == 0:
        raise ParameterError(f"{name} must be a non-empty 1-D sequence of numbers")
    if not np.all(np.isfinite(v)):
        raise ParameterError(f"{name} must be finite numbers")
    if v.size > 1 and not np.all(np.diff(v) > 0):
        raise ParameterError(f"{name} must be strictly increasing, got {v.tolist()}")
    return v


def _check_params(tau_s_values: np.ndarray, dt0_c_values: np.ndarray) -> None:
    # ThermalParams validates the ranges and words the message
    for tau in (tau_s_values[0], tau_s_values[-1]):
        for dt0 in (dt0_c_values[0], dt0_c_values[-1]):
            ThermalParams(tau_s=float(tau), dt0_c=float(dt0))


def _deltas(deltas_c_per_min) -> tuple[float, ...]:
    d = tuple(float(x) for x in np.atleast_1d(np.asarray(deltas_c_per_min, dtype=float)))
    if not d:
        raise ParameterError("deltas_c_per_min needs at least one gradient separation, °C/min")
    for x in d:
        if not (math.isfinite(x) and x > 0):
            raise ParameterError(f"every delta_c_per_min must be > 0 °C/min, got {x}")
    if len(set(d)) != len(d):
        raise ParameterError(f"deltas_c_per_min has repeated values: {d}")
    return d


def delta_tag(delta_c_per_min: float) -> str:
    """Column suffix of a gradient separation: 0.05 -> ``delta_0p05``, 0.1 -> ``delta_0p1``."""
    return "delta_" + f"{delta_c_per_min:g}".replace(".", "p").replace("-", "m")


# ---------------------------------------------------------------------------------------
# backends
# ---------------------------------------------------------------------------------------
def _progress_bar(total: int, progress: bool | Progress, desc: str | None):
    """A tqdm bar on a terminal, periodic lines in a log, nothing when ``progress`` is off."""
    reporter = progress if isinstance(progress, Progress) else Progress(enabled=bool(progress))
    return reporter.bar(total, desc or "")


def _die_with_parent(main_pid: int) -> None:
    """Initializer of the local pool's workers: exit as soon as the pool's owner is gone.

    A worker busy planning would otherwise outlive a killed ``schedsyn campaign`` by
    minutes. A daemon thread waits on the pipe multiprocessing keeps open between the
    worker and the process that started it (``multiprocessing.parent_process()``): the
    kernel closes it when that process dies, even before its exit is collected, and the
    worker exits at once. Without that pipe the thread checks every 0.5 s that
    ``main_pid`` is alive. On Linux the worker also asks the kernel for SIGKILL when its
    own parent dies (``prctl(PR_SET_PDEATHSIG)``; the parent is the owner itself with the
    fork and spawn start methods).
    """
    import multiprocessing
    import signal as _signal
    import threading

    # Ctrl-C reaches the whole foreground process group: the owner stops the pool (and
    # kills its workers, :func:`_stop_broken_pool`); a worker that took the
    # KeyboardInterrupt itself printed a traceback, and one interrupted inside the call
    # queue's lock left the owner's shutdown waiting for ever (red team, 1 in 7 runs)
    _signal.signal(_signal.SIGINT, _signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            pr_set_pdeathsig = 1
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL))
        except (OSError, AttributeError):  # no libc prctl: the thread below still works
            pass
    parent = multiprocessing.parent_process()
    threading.Thread(
        target=_watch_parent, args=(parent, main_pid), daemon=True, name="schedsyn-watch-parent"
    ).start()


def _watch_parent(parent, main_pid: int) -> None:
    import time

    if parent is not None and getattr(parent, "_sentinel", None) is not None:
        parent.join()  # returns when the owner's end of the pipe closes: it died
        os._exit(1)
    while _alive(main_pid):
        time.sleep(0.5)
    os._exit(1)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet collected, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state not in ("Z", "X")


def _is_dask_address(backend: str) -> bool:
    return "://" in backend


def _local_context():
    # forkserver: no fork() of a multi-threaded parent (deadlock-prone; warns on 3.12+);
    # the server imports schedsyn.sweep once, so each worker starts in milliseconds.
    import multiprocessing as mp

    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(["schedsyn.sweep"])
        return ctx
    return mp.get_context("spawn")


def run_map(
    func: Callable[[Any], Any],
    items: Iterable[Any],
    backend: Any = "local",
    *,
    workers: int | None = None,
    progress: bool | Progress = True,
    desc: str | None = None,
) -> list[Any]:
    """``[func(x) for x in items]`` on a backend, in the order of ``items``.

    Parameters
    ----------
    func : callable
        Picklable (a module-level function or a ``functools.partial`` of one) for every
        backend but ``"serial"``.
    items : iterable
        Picklable arguments, one call each.
    backend : str or distributed.Client
        ``"serial"`` (this process), ``"local"`` (a process pool on this machine's cores;
        ``workers=1`` runs serially) or a Dask scheduler address ``"tcp://HOST:PORT"``
        (any ``scheme://...`` that :class:`distributed.Client` accepts), or a connected
        ``distributed.Client``. The workers of a remote cluster need schedsyn installed.
    workers : int, optional
        Process count of the local pool (default: the number of cores, at most
        ``len(items)``). Ignored by the other backends.
    progress : bool or Progress
        Count finished items on stderr: a tqdm bar on a terminal, timestamped lines in a
        log (see :class:`schedsyn.progress.Progress`); False: silent.

    Raises
    ------
    ParameterError
        Unknown backend or bad worker count.
    SchedsynError
        The Dask backend without ``dask[distributed]`` installed, or an unreachable
        scheduler. Exceptions raised by ``func`` propagate unchanged.
    EnvironmentFaultError
        A worker process of the local pool died (killed, out of memory).

    Notes
    -----
    The local pool's workers die with the process that started them (see
    :func:`_die_with_parent`), so a killed caller leaves no worker running.
    """
    items = list(items)
    if workers is not None and (int(workers) != workers or workers < 1):
        raise ParameterError(f"workers must be a whole number >= 1, got {workers!r}")
    if not items:
        return []
    if hasattr(backend, "submit") and hasattr(backend, "gather"):
        return _run_dask_client(backend, func, items, progress, desc)
    if not isinstance(backend, str):
        raise ParameterError(
            f"backend must be 'serial', 'local' or a Dask scheduler address, got {backend!r}"
        )
    if backend == "serial" or (backend == "local" and (workers == 1 or len(items) == 1)):
        out = []
        with _progress_bar(len(items), progress, desc) as bar:
            for x in items:
                out.append(func(x))
                bar.update(1)
        return out
    if backend == "local":
        return _run_local(func, items, workers, progress, desc)
    if _is_dask_address(backend):
        return _run_dask(backend, func, items, progress, desc)
    raise ParameterError(
        f"backend must be 'serial', 'local' or a Dask scheduler address like "
        f"tcp://HOST:PORT, got {backend!r}"
    )


def _run_local(func, items, workers, progress, desc) -> list[Any]:
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    n = min(int(workers) if workers else (os.cpu_count() or 1), len(items))
    out: list[Any] = [None] * len(items)
    pool = ProcessPoolExecutor(
        max_workers=n,
        mp_context=_local_context(),
        initializer=_die_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        futures = {pool.submit(func, x): i for i, x in enumerate(items)}
        with _progress_bar(len(items), progress, desc) as bar:
            for fut in as_completed(futures):
                out[futures[fut]] = fut.result()
                bar.update(1)
    except BrokenProcessPool as exc:
        _stop_broken_pool(pool)
        raise EnvironmentFaultError(
            f"a worker process of the local pool died ({exc}): killed, or out of memory; "
            "when calling schedsyn from a script, guard its entry point with "
            "`if __name__ == '__main__':`, or use the serial backend"
        ) from None
    except BaseException:
        # interrupted (Ctrl-C), or func raised: the results still running are not wanted,
        # so the workers are stopped now instead of waited for (up to 17 s after Ctrl-C,
        # and for ever once, red team)
        _stop_broken_pool(pool)
        raise
    pool.shutdown(wait=True)
    return out


#: How long a broken pool's workers are killed and waited for, s.
BROKEN_POOL_WAIT_S = 60.0


def _stop_broken_pool(pool) -> None:
    """Shut a pool with a dead worker (or an interrupted one) down without hanging.

    The executor's own clean-up terminates the other workers and joins them, but a worker
    the terminate missed (CI, 2026-12-03: one still reading its call queue 10 min later,
    the suite hung) is joined forever. So the workers are killed here, again every half
    second, until the executor's manager thread has finished (at most
    :data:`BROKEN_POOL_WAIT_S`)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    manager = getattr(pool, "_executor_manager_thread", None)
    deadline = time.monotonic() + BROKEN_POOL_WAIT_S
    while True:
        for p in procs:
            try:
                if p.is_alive():
                    p.kill()
            except (OSError, ValueError, AttributeError):  # gone, or closed already
                pass
        if manager is None or not manager.is_alive() or time.monotonic() > deadline:
            return
        manager.join(timeout=0.5)


def _run_dask(address: str, func, items, progress, desc) -> list[Any]:
    try:
        from distributed import Client
    except ImportError:
        raise SchedsynError(
            "the Dask backend needs dask[distributed]: pip install 'schedsyn[dask]' "
            "(or run without --dask)"
        ) from None
    from distributed.comm.registry import get_backend

    try:
        get_backend(address.split("://", 1)[0])  # check the scheme before connecting
    except ValueError as exc:
        raise ParameterError(f"Dask scheduler address {address!r}: {exc}") from None
    try:
        client = Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SchedsynError(
            f"cannot reach the Dask scheduler at {address} ({first}); start one with "
            "`dask scheduler` and workers with `dask worker ADDRESS`, or run without --dask"
        ) from None
    try:
        return _run_dask_client(client, func, items, progress, desc)
    finally:
        client.close()


def _run_dask_client(client, func, items, progress, desc) -> list[Any]:
    from distributed import as_completed

    futures = client.map(func, items, pure=False)
    with _progress_bar(len(items), progress, desc) as bar:
        for _ in as_completed(futures, loop=client.loop):
            bar.update(1)
    return client.gather(futures)


# ---------------------------------------------------------------------------------------
# fixed-plan sweep
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _TauChunk:
    """One ``tau`` row of a fixed-plan sweep (the unit of parallel work; picklable)."""

    programme: Programme
    grid: BinGrid
    tau_s: float
    dt0_c_values: tuple[float, ...]
    levels_required: int
    deltas_c_per_min: tuple[float, ...]
    dt_min: float
    t0_c: float
    #: an augmented model (a :class:`~schedsyn.effects.ModelSpec`), or None: the
    #: first-order lag
    model: Any = None

    def trajectory(self, dt0_c: float, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(T, g)`` of the augmented model at ``(tau_s, dt0_c)`` (the effect case)."""
        pred = point_model(self.model, self.tau_s, dt0_c).predict(
            self.programme, times, t0_c=self.t0_c
        )
        return pred.t_c, pred.g_c_per_min


#: Effects whose own parameters are the device's time constants (the base ``tau_s`` is
#: not used): a sweep scales them with the grid point's tau.
TAU_PARAMETERS = {"asymmetric_tau": ("tau_heat_s", "tau_cool_s")}


def point_model(model, tau_s: float, dt0_c: float):
    """``model`` (a :class:`~schedsyn.effects.ModelSpec`) at one grid point: its base
    ``tau_s`` and ``dt0_c`` replaced; an effect whose parameters are the time constants
    themselves (:data:`TAU_PARAMETERS`: heating and cooling taus) gets them times
    ``tau_s / model.tau_s``, so that the model's own point is the model and a sweep
    along tau changes them (the base tau is unused there)."""
    from .effects import ModelSpec

    params = dict(model.parameters)
    for name in TAU_PARAMETERS.get(model.effect, ()):
        params[name] *= tau_s / model.tau_s
    return ModelSpec(tau_s, dt0_c, model.effect, params)


def _sweep_tau(chunk: _TauChunk) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coverage and min levels ``(n_dt0, n_delta)`` and T range ``(n_dt0,)`` for one tau."""
    prog = chunk.programme
    times = dense_times(prog.total_min, chunk.dt_min)
    trajectory: Callable[[float, np.ndarray], tuple[np.ndarray, np.ndarray]]
    if chunk.model is not None:  # an augmented model: one prediction per point
        trajectory = chunk.trajectory
    else:
        # A(tau) does not depend on dT0: one affine response for the whole row
        resp = affine_response(
            FirstOrderLag(ThermalParams(tau_s=chunk.tau_s, dt0_c=0.0)),
            prog.durations_min,
            times,
            prog.start_c,
            chunk.t0_c,
        )
        t_forced = resp.a_t @ prog.rates_c_per_min  # A_T u
        g_forced = resp.a_g @ prog.rates_c_per_min  # A_g u

        def first_order(dt0: float, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # b(tau, dT0): the free response, the only place dT0 enters
            b_t, b_g = FirstOrderLag(ThermalParams(tau_s=chunk.tau_s, dt0_c=dt0)).free(
                times, prog.start_c, chunk.t0_c
            )
            return t_forced + b_t, g_forced + b_g  # T = A_T u + b_T, g = A_g u + b_g

        trajectory = first_order

    n_dt0, n_delta = len(chunk.dt0_c_values), len(chunk.deltas_c_per_min)
    cov = np.empty((n_dt0, n_delta))
    lev = np.empty((n_dt0, n_delta), dtype=np.int64)
    t_lo = np.empty(n_dt0)
    t_hi = np.empty(n_dt0)
    for i, dt0 in enumerate(chunk.dt0_c_values):
        temp, grad = trajectory(dt0, times)
        t_lo[i], t_hi[i] = temp.min(), temp.max()
        for j, delta in enumerate(chunk.deltas_c_per_min):
            rep = coverage_report(temp, grad, chunk.grid, chunk.levels_required, delta)
            cov[i, j] = rep.coverage
            lev[i, j] = rep.min_levels
    return cov, lev, t_lo, t_hi


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True)
class SweepResult:
    """Coverage of one programme over a ``tau_s`` x ``dt0_c`` grid.

    Attributes
    ----------
    region_c : (float, float)
        Working region, degC.
    tau_s_values : array (n_tau,)
        Time constants, s.
    dt0_c_values : array (n_dt0,)
        Self-heating offsets, degC.
    levels_required : int
        Distinct gradient levels a bin needs to count as covered.
    deltas_c_per_min : tuple of float
        Gradient separations, degC/min; the first one is *the* coverage (``coverage``,
        ``min_levels`` columns).
    coverage : array (n_tau, n_dt0, n_delta)
        Fraction of bins covered, 0..1.
    min_levels : array (n_tau, n_dt0, n_delta)
        Fewest distinct levels of any bin.
    t_min_c, t_max_c : array (n_tau, n_dt0)
        Range of the internal temperature over the programme, degC.
    bin_c : float
        Bin width, degC.
    model : ModelSpec or None
        The augmented model swept over its base ``tau`` and ``dT0``, its effect held
        (None: the first-order lag).
    """

    region_c: tuple[float, float]
    tau_s_values: np.ndarray
    dt0_c_values: np.ndarray
    levels_required: int
    deltas_c_per_min: tuple[float, ...]
    coverage: np.ndarray
    min_levels: np.ndarray
    t_min_c: np.ndarray
    t_max_c: np.ndarray
    bin_c: float = 1.0
    model: Any = None

    def __post_init__(self) -> None:
        for name in (
            "tau_s_values",
            "dt0_c_values",
            "coverage",
            "min_levels",
            "t_min_c",
            "t_max_c",
        ):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    # -- views at the first (primary) delta ----------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return (self.tau_s_values.size, self.dt0_c_values.size)

    @property
    def coverage_grid(self) -> np.ndarray:
        """Coverage at the first delta, ``(n_tau, n_dt0)``."""
        return self.coverage[:, :, 0]

    @property
    def min_levels_grid(self) -> np.ndarray:
        """Min distinct levels at the first delta, ``(n_tau, n_dt0)``."""
        return self.min_levels[:, :, 0]

    def covered_mask(self, min_coverage: float = 1.0) -> np.ndarray:
        """``(n_tau, n_dt0)`` True where coverage at the first delta >= ``min_coverage``."""
        return self.coverage_grid >= min_coverage - 1e-12

    def holds(self, min_coverage: float = 1.0) -> bool:
        """Whether every grid point reaches ``min_coverage`` (at the first delta)."""
        return bool(np.all(self.covered_mask(min_coverage)))

    @property
    def full_share(self) -> float:
        """Share of grid points with complete coverage (at the first delta)."""
        return float(np.mean(self.covered_mask(1.0)))

    def covered_box(
        self,
        min_coverage: float = 1.0,
        also: np.ndarray | None = None,
        containing: tuple[int, int] | None = None,
    ) -> dict[str, Any] | None:
        """Largest axis-aligned sub-box of grid points that all reach ``min_coverage``.

        "Largest" counts grid points (ties: the first found, smallest tau then dT0).
        Returns ``{"tau_s_range": (lo, hi), "dt0_c_range": (lo, hi), "n_points": n}``
        or None when no point reaches ``min_coverage``. Used to say which part of a box
        a plan covers. ``also``: an ``(n_tau, n_dt0)`` mask the points must hold too (the
        device within its limits); ``containing``: only boxes holding that grid point
        ``(i_tau, j_dt0)`` (the nominal point a plan was made for).
        """
        mask = self.covered_mask(min_coverage)
        if also is not None:
            mask = mask & also
        ok = mask.astype(np.int64)
        n_tau, n_dt0 = ok.shape
        # prefix sums: points covered in [i0, i1) x [j0, j1) in O(1)
        s = np.zeros((n_tau + 1, n_dt0 + 1), dtype=np.int64)
        s[1:, 1:] = ok.cumsum(0).cumsum(1)
        best, best_n = None, 0
        for i0 in range(n_tau):
            for i1 in range(i0 + 1, n_tau + 1):
                for j0 in range(n_dt0):
                    for j1 in range(j0 + 1, n_dt0 + 1):
                        n = (i1 - i0) * (j1 - j0)
                        if n <= best_n:
                            continue
                        if containing is not None and not (
                            i0 <= containing[0] < i1 and j0 <= containing[1] < j1
                        ):
                            continue
                        if s[i1, j1] - s[i0, j1] - s[i1, j0] + s[i0, j0] == n:
                            best, best_n = (i0, i1, j0, j1), n
        if best is None:
            return None
        i0, i1, j0, j1 = best
        return {
            "tau_s_range": (float(self.tau_s_values[i0]), float(self.tau_s_values[i1 - 1])),
            "dt0_c_range": (float(self.dt0_c_values[j0]), float(self.dt0_c_values[j1 - 1])),
            "n_points": best_n,
        }

    def device_excess_c(self, device_min_c: float, device_max_c: float) -> np.ndarray:
        """``(n_tau, n_dt0)``: how far the internal temperature goes past the device
        limits at each grid point, degC (0 where it stays within them).

        A plan keeps the device within its limits at the nominal point only; off it the
        same programme can overshoot (a larger dT0 or a shorter tau follows the chamber
        further).
        """
        over = np.maximum(self.t_max_c - device_max_c, device_min_c - self.t_min_c)
        return np.maximum(over, 0.0)

    def worst(self) -> dict[str, float]:
        """The grid point with the lowest coverage (then fewest levels) at the first delta."""
        cov, lev = self.coverage_grid.ravel(), self.min_levels_grid.ravel()
        k = int(np.lexsort((lev, cov))[0])
        i, j = np.unravel_index(k, self.shape)
        return {
            "tau_s": float(self.tau_s_values[i]),
            "dt0_c": float(self.dt0_c_values[j]),
            "coverage": float(cov[k]),
            "min_levels": int(lev[k]),
        }

    def to_frame(self) -> pd.DataFrame:
        """One row per grid point (``tau_s`` outer, ``dt0_c`` inner).

        Columns: ``tau_s, dt0_c, coverage, min_levels`` (at the first delta), then
        ``coverage_delta_<d>, min_levels_delta_<d>`` for every delta (``0.05 -> 0p05``),
        then ``t_min_c, t_max_c``.
        """
        tau, dt0 = np.meshgrid(self.tau_s_values, self.dt0_c_values, indexing="ij")
        cols: dict[str, np.ndarray] = {
            "tau_s": tau.ravel(),
            "dt0_c": dt0.ravel(),
            "coverage": self.coverage[:, :, 0].ravel(),
            "min_levels": self.min_levels[:, :, 0].ravel(),
        }
        for j, d in enumerate(self.deltas_c_per_min):
            cols[f"coverage_{delta_tag(d)}"] = self.coverage[:, :, j].ravel()
            cols[f"min_levels_{delta_tag(d)}"] = self.min_levels[:, :, j].ravel()
        cols["t_min_c"] = self.t_min_c.ravel()
        cols["t_max_c"] = self.t_max_c.ravel()
        return pd.DataFrame(cols)

    def summary(self) -> str:
        """Coverage range, worst point and the share of the grid with full coverage."""
        w = self.worst()
        cov = self.coverage_grid
        lo, hi = self.region_c
        through = ""
        if self.model is not None:
            held = ", ".join(f"{k} {v:g}" for k, v in self.model.parameters.items())
            scaled = TAU_PARAMETERS.get(self.model.effect, ())
            if scaled:
                held += f"; {' and '.join(scaled)} scaled with each point's tau"
            through = f" through the model's {self.model.effect}" + (f" ({held})" if held else "")
        return (
            f"sweep of [{lo:g}, {hi:g}] °C{through} over tau {self.tau_s_values[0]:g} .. "
            f"{self.tau_s_values[-1]:g} s x dT0 {self.dt0_c_values[0]:g} .. "
            f"{self.dt0_c_values[-1]:g} °C ({cov.size} points, >= {self.levels_required} "
            f"levels {self.deltas_c_per_min[0]:g} °C/min apart): coverage "
            f"{cov.min():.1%} .. {cov.max():.1%}; worst at tau {w['tau_s']:g} s, dT0 "
            f"{w['dt0_c']:g} °C ({w['coverage']:.1%}, min {w['min_levels']} levels); full "
            f"coverage on {self.full_share:.1%} of the grid"
        )


def sweep_fixed(
    programme: Programme,
    region: tuple[float, float],
    tau_s_values: Sequence[float] | np.ndarray,
    dt0_c_values: Sequence[float] | np.ndarray,
    *,
    levels_required: int = 6,
    deltas_c_per_min: Sequence[float] = (0.05, 0.1),
    dt_min: float = 0.1,
    bin_c: float = 1.0,
    t0_c: float = 20.0,
    backend: Any = "serial",
    workers: int | None = None,
    progress: bool | Progress = False,
    model: Any = None,
) -> SweepResult:
    """Coverage of a fixed ``programme`` at every ``(tau_s, dt0_c)`` grid point.

    Each point is exactly ``coverage_report(simulate(programme, ThermalParams(tau, dt0),
    dt_min=dt_min, t0_c=t0_c))`` on ``BinGrid(*region, bin_c)``, computed with one affine
    response per ``tau`` (see the module doc); with an augmented ``model``, the model
    with its base ``tau`` and ``dT0`` replaced by the point's, predicted on the same times.

    Parameters
    ----------
    programme : Programme
        The chamber programme under test.
    region : (lo_c, hi_c)
        Working region, degC.
    tau_s_values, dt0_c_values : sequence of float
        Strictly increasing grid axes: time constants (s, > 0) and offsets (degC).
    levels_required : int
        Distinct gradient levels per bin (default 6, the paper's redundancy).
    deltas_c_per_min : sequence of float
        Gradient separations of distinct levels, degC/min; the first is the primary one.
    dt_min : float
        Simulation step, min.
    t0_c : float
        Internal temperature at t = 0, degC.
    backend, workers, progress :
        See :func:`run_map`; the grid is split into one task per ``tau`` value. The result
        does not depend on the backend.
    model : ModelSpec, optional
        An augmented model (:class:`schedsyn.effects.ModelSpec`, e.g. from ``schedsyn
        diagnose``): its effect is held at its parameters while the grid replaces its
        base ``tau_s`` and ``dt0_c``. Its own ``tau_s``/``dt0_c`` are not a grid point
        unless the axes hold them. Default: the first-order lag alone.
    """
    if not isinstance(programme, Programme):
        raise ParameterError(f"programme must be a Programme, got {type(programme).__name__}")
    lo, hi = (float(x) for x in region)
    grid = BinGrid(lo, hi, float(bin_c))
    taus = _axis(tau_s_values, "tau_s_values")
    dt0s = _axis(dt0_c_values, "dt0_c_values")
    _check_params(taus, dt0s)
    deltas = _deltas(deltas_c_per_min)
    if int(levels_required) != levels_required or levels_required < 1:
        raise ParameterError(f"levels_required must be a whole number >= 1, got {levels_required}")
    dense_times(programme.total_min, dt_min)  # validates dt_min
    model = _checked_model(model, taus, dt0s)
    chunks = [
        _TauChunk(
            programme,
            grid,
            float(tau),
            tuple(float(x) for x in dt0s),
            int(levels_required),
            deltas,
            float(dt_min),
            float(t0_c),
            model,
        )
        for tau in taus
    ]
    rows = run_map(
        _sweep_tau, chunks, backend, workers=workers, progress=progress, desc="sweep (tau rows)"
    )
    return SweepResult(
        region_c=(lo, hi),
        tau_s_values=taus,
        dt0_c_values=dt0s,
        levels_required=int(levels_required),
        deltas_c_per_min=deltas,
        coverage=np.stack([r[0] for r in rows]),
        min_levels=np.stack([r[1] for r in rows]),
        t_min_c=np.stack([r[2] for r in rows]),
        t_max_c=np.stack([r[3] for r in rows]),
        bin_c=float(bin_c),
        model=model,
    )


def _checked_model(model: Any, taus: np.ndarray, dt0s: np.ndarray):
    """The augmented model for :func:`sweep_fixed`, checked at the grid's corners (a model
    that cannot take a grid point fails here, in one line, not in a worker); None for
    none or for effect "none" (the first-order lag's fast path)."""
    if model is None:
        return None
    from .effects import ModelSpec

    if not isinstance(model, ModelSpec):
        raise ParameterError(
            f"model must be a schedsyn.effects.ModelSpec (a model file read by "
            f"schedsyn.models_io.load_model), got {type(model).__name__}"
        )
    if model.effect == "none":
        return None
    for tau in (taus[0], taus[-1]):
        for dt0 in (dt0s[0], dt0s[-1]):
            point_model(model, float(tau), float(dt0))
    return model


def verify_box(
    programme: Programme,
    region: tuple[float, float],
    tau_s_range: tuple[float, float],
    dt0_c_range: tuple[float, float],
    n_tau: int = MIN_VERIFY_N_TAU,
    n_dt0: int = MIN_VERIFY_N_DT0,
    *,
    levels_required: int = 6,
    deltas_c_per_min: Sequence[float] = (0.05, 0.1),
    dt_min: float = 0.1,
    bin_c: float = 1.0,
    t0_c: float = 20.0,
    backend: Any = "serial",
    workers: int | None = None,
    progress: bool | Progress = False,
) -> SweepResult:
    """Dense fixed-plan sweep over the box ``tau_s_range`` x ``dt0_c_range`` (ends included).

    Used to check a robust plan everywhere in its box, not only at its design scenarios:
    ``verify_box(...).holds()`` is True when every point has full coverage, and
    ``.covered_mask()`` shows which part of the box is covered. At least
    ``MIN_VERIFY_N_TAU`` x ``MIN_VERIFY_N_DT0`` (9 x 7) points; an axis whose range is a
    single value (``lo == hi``) has one point.
    """
    axes = []
    for name, rng, n, n_min, unit in (
        ("tau_s_range", tau_s_range, n_tau, MIN_VERIFY_N_TAU, "s"),
        ("dt0_c_range", dt0_c_range, n_dt0, MIN_VERIFY_N_DT0, "°C"),
    ):
        try:
            lo, hi = (float(x) for x in rng)
        except (TypeError, ValueError):
            raise ParameterError(f"{name} must be a pair (lo, hi) in {unit}, got {rng!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ParameterError(f"{name} must be finite with lo <= hi {unit}, got {rng!r}")
        if int(n) != n or n < n_min:
            raise ParameterError(
                f"a verification sweep needs at least {n_min} points along {name}, got {n}"
            )
        axes.append(np.array([lo]) if lo == hi else np.linspace(lo, hi, int(n)))
    return sweep_fixed(
        programme,
        region,
        axes[0],
        axes[1],
        levels_required=levels_required,
        deltas_c_per_min=deltas_c_per_min,
        dt_min=dt_min,
        bin_c=bin_c,
        t0_c=t0_c,
        backend=backend,
        workers=workers,
        progress=progress,
    )


# ---------------------------------------------------------------------------------------
# re-plan sweep
# ---------------------------------------------------------------------------------------
def _replan_point(plan_fn: Callable[[ThermalParams], Any], params: ThermalParams) -> dict:
    """Summary row of one re-plan; a failed plan is a row, not the end of the sweep."""
    row: dict[str, Any] = {"tau_s": params.tau_s, "dt0_c": params.dt0_c}
    try:
        result = plan_fn(params)
    except InfeasiblePlanError as exc:
        row.update(status="infeasible", message=str(exc))
        if exc.best_coverage is not None:
            row["best_coverage"] = exc.best_coverage
        return row
    except SchedsynError as exc:
        row.update(status="failed", message=f"{type(exc).__name__}: {exc}")
        return row
    summary = dict(result.to_summary_dict())
    for key in ("tau_s", "dt0_c"):
        summary.pop(key, None)  # the grid point is authoritative
    row.update(status="ok", message="")
    row.update(summary)
    return row


@dataclass(frozen=True, slots=True)
class ReplanResult:
    """One re-plan per grid point: ``rows`` of plain summary dicts (``tau_s`` outer)."""

    tau_s_values: np.ndarray
    dt0_c_values: np.ndarray
    rows: tuple[dict, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "tau_s_values", _frozen(self.tau_s_values))
        object.__setattr__(self, "dt0_c_values", _frozen(self.dt0_c_values))

    @property
    def n_ok(self) -> int:
        return sum(r["status"] == "ok" for r in self.rows)

    def to_frame(self) -> pd.DataFrame:
        """Columns ``tau_s, dt0_c, status, message`` then the planner's summary keys."""
        return pd.DataFrame(list(self.rows))

    def summary(self) -> str:
        """Plans found, and the range of each numeric summary column over the grid."""
        frame = self.to_frame()
        text = f"re-planned {len(self.rows)} points: {self.n_ok} plans found"
        bad = len(self.rows) - self.n_ok
        if bad:
            text += f", {bad} infeasible or failed"
        ok = frame[frame["status"] == "ok"]
        parts = []
        for col in ok.columns:
            if col in ("tau_s", "dt0_c") or not pd.api.types.is_numeric_dtype(ok[col]):
                continue
            if pd.api.types.is_bool_dtype(ok[col]) or ok[col].isna().all():
                continue
            if len(ok) > 1 and ok[col].nunique() == 1:
                continue  # the same at every point (e.g. the region): not a sensitivity
            parts.append(f"{col} {ok[col].min():.4g} .. {ok[col].max():.4g}")
        if parts:
            text += "; " + "; ".join(parts)
        return text


def sweep_replan(
    plan_fn: Callable[[ThermalParams], Any],
    tau_s_values: Sequence[float] | np.ndarray,
    dt0_c_values: Sequence[float] | np.ndarray,
    *,
    backend: Any = "serial",
    workers: int | None = None,
    progress: bool | Progress = False,
) -> ReplanResult:
    """Call ``plan_fn(ThermalParams(tau, dt0))`` at every grid point through :func:`run_map`.

    ``plan_fn`` returns an object with ``.to_summary_dict()`` (plain numbers / strings,
    e.g. duration and coverage margin). An :class:`InfeasiblePlanError` or other
    :class:`SchedsynError` at a point becomes a row with ``status`` ``"infeasible"`` /
    ``"failed"`` and the message; any other exception propagates. For the process and
    Dask backends ``plan_fn`` must be picklable (module-level function, ``partial`` of
    one, or an instance of a module-level class).
    """
    taus = _axis(tau_s_values, "tau_s_values")
    dt0s = _axis(dt0_c_values, "dt0_c_values")
    _check_params(taus, dt0s)
    points = [ThermalParams(tau_s=float(t), dt0_c=float(d)) for t in taus for d in dt0s]
    rows = run_map(
        partial(_replan_point, plan_fn),
        points,
        backend,
        workers=workers,
        progress=progress,
        desc="re-plan",
    )
    return ReplanResult(taus, dt0s, tuple(rows))
