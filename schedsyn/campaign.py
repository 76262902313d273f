"""A campaign: several experiments planned with one model and one chamber.

The paper splits -50 .. +60 degC into four working regions, one 9-hour experiment each
(:func:`default_campaign`). A campaign is described by a TOML file (the paper's one ships
with the package, :data:`PAPER_CAMPAIGN_TOML`, and is ``data/paper_campaign.toml`` in the
repository; copy and edit it)::

    [model]        tau_s, dt0_c                        (ThermalParams)
    [chamber]      preset = "binder-mk-56"             (optional: a chamber preset's rates,
                   floor, ceiling and max_steps; [limits] and max_steps keys override it;
                   see schedsyn.chambers)
    [limits]       chamber_min_c, duration_max_min ... (Limits; any field)
    [settings]     levels_required, delta_c_per_min, segment_min, objective, ...
                   (ExperimentSpec fields shared by every experiment), and
                   shorten = true (the whole campaign: plan_campaign's ``shorten``)
    [robust]       tau_s = [LO, HI], dt0_c = [LO, HI]  (optional robust box)
    [export]       controller = "espec-p300" (or a list), first_programme, max_steps,
                   programmes, end_mode  (optional: controller programmes, see
                   schedsyn.export)
    [sheet]        start = "2026-11-24 08:00", interval_min, band_tau_rel, band_dt0_c,
                   n_tau  (optional: operator sheets, see schedsyn.checkpoints)
    [[experiment]] name, working_lo_c, working_hi_c, approx_lo_c, approx_hi_c,
                   any setting to override, baseline_steps = "FILE.csv" (optional,
                   relative to the TOML file)

:func:`plan_campaign` plans every experiment (in parallel over the local cores through
:func:`schedsyn.sweep.run_map`) and returns a :class:`CampaignResult` whose
``summary_frame()`` puts each plan next to the paper-like baseline, if any.
:func:`chamber_requirement` answers "what chamber do I need?": coverage as a function
of the chamber floor and ceiling.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import math
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .chambers import LIMIT_FIELDS, ChamberPreset, chamber_preset
from .checkpoints import SheetSettings, parse_start
from .coverage import coverage_report
from .design import DesignSpace, plan_design, programme_design
from .errors import InfeasiblePlanError, ParameterError, SchedsynError
from .export import ExportSettings
from .params import Limits, ThermalParams
from .planner import (
    ExperimentSpec,
    Plan,
    check_device_start,
    plan_experiment,
    planning_effort,
)
from .programme import read_steps
from .progress import Progress
from .simulate import simulate
from .sweep import run_map

#: Files the package ships in ``schedsyn/data`` (installed with the wheel; the
#: repository's top-level ``data/`` keeps identical copies for the examples).
_EXTRACTED = contextlib.ExitStack()
atexit.register(_EXTRACTED.close)


def package_data(name: str) -> Path:
    """Filesystem path of ``schedsyn/data/<name>``, found with :mod:`importlib.resources`.

    An ordinary installation (a wheel, an editable install, a checkout) has the file on
    disk; from a zipped installation it is extracted once, for the life of the process.
    """
    resource = resources.files("schedsyn").joinpath("data").joinpath(name)
    if not resource.is_file():
        raise SchedsynError(
            f"package data file {name} is missing from the schedsyn installation; "
            "reinstall schedsyn (pip install --force-reinstall schedsyn)"
        )
    if isinstance(resource, Path):
        return resource.resolve()
    return _EXTRACTED.enter_context(resources.as_file(resource))


#: The paper's campaign (copy it to start your own) and the paper-like baseline of
#: experiment 1 that the campaign names; both inside the installed package.
PAPER_CAMPAIGN_TOML = package_data("paper_campaign.toml")
PAPER_BASELINE_EXP1 = package_data("baseline_exp1_steps.csv")
#: The folder holding them.
DATA_DIR = PAPER_CAMPAIGN_TOML.parent


def _shipped(name: str) -> bool:
    """Whether ``name`` is a step table shipped inside the package (``schedsyn/data``)."""
    return name.endswith(".csv") and (DATA_DIR / name).is_file()


#: The paper's regions: (name, working lo, working hi, approximation lo, approximation hi).
PAPER_REGIONS_C = (
    ("W1", -50.0, -30.0, -52.0, -20.0),
    ("W2", -30.0, 0.0, -40.0, 10.0),
    ("W3", 0.0, 30.0, -10.0, 40.0),
    ("W4", 30.0, 60.0, 20.0, 60.0),
)

_REGION_KEYS = ("name", "working_lo_c", "working_hi_c", "approx_lo_c", "approx_hi_c")
_SETTING_KEYS = tuple(
    f.name for f in dataclasses.fields(ExperimentSpec) if f.name not in _REGION_KEYS
)
_INT_KEYS = ("levels_required", "max_steps")
_STR_KEYS = ("name", "objective")


@dataclass(frozen=True, slots=True)
class CampaignConfig:
    """Experiments planned with one model and one chamber.

    Parameters
    ----------
    experiments : tuple of ExperimentSpec
        At least one; names must be distinct (they name the output folders).
    params : ThermalParams
        Nominal model parameters.
    limits : Limits
        Chamber, device and duration limits shared by every experiment.
    robust_tau_s, robust_dt0_c : (lo, hi), optional
        Robust box: each programme must cover its region for every (tau, dT0) in it.
    baseline_steps : tuple of (Path or None)
        Empty, or one entry per experiment: a paper-like step table to compare with.
    exports : tuple of ExportSettings
        Controller programmes written beside each step table (``[export]``).
    sheet : SheetSettings
        Operator sheets: start time, checkpoint interval, band (``[sheet]``).
    shorten : bool
        Give each complete plan to the timetable stage for a shorter one (``shorten =
        true`` in ``[settings]``; :func:`plan_campaign`). Only with the ``shortest``
        objective and no robust box.
    """

    experiments: tuple[ExperimentSpec, ...]
    params: ThermalParams = field(default_factory=ThermalParams)
    limits: Limits = field(default_factory=Limits)
    robust_tau_s: tuple[float, float] | None = None
    robust_dt0_c: tuple[float, float] | None = None
    baseline_steps: tuple[Path | None, ...] = ()
    exports: tuple[ExportSettings, ...] = ()
    sheet: SheetSettings = field(default_factory=SheetSettings)
    shorten: bool = False

    def __post_init__(self) -> None:
        exps = tuple(self.experiments)
        if not exps or not all(isinstance(e, ExperimentSpec) for e in exps):
            raise ParameterError("a campaign needs at least one experiment (ExperimentSpec)")
        names = [e.name for e in exps]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ParameterError(f"experiment names must be distinct, repeated: {dup}")
        for n in names:
            if any(c in n for c in "/\\") or n in (".", ".."):
                raise ParameterError(
                    f"experiment name {n!r} cannot name a folder; use letters, digits, '-' or '_'"
                )
        object.__setattr__(self, "experiments", exps)
        # a device starting past its own limit is bad input, refused before any planning
        # (not after minutes of search ending in "lengthen the duration")
        check_device_start(self.limits)
        for key in ("robust_tau_s", "robust_dt0_c"):
            v = getattr(self, key)
            if v is not None:
                v = tuple(float(x) for x in v)
                if len(v) != 2 or not all(math.isfinite(x) for x in v) or v[0] > v[1]:
                    raise ParameterError(f"{key} must be (lo, hi) with lo <= hi, got {v}")
                object.__setattr__(self, key, v)
        base = tuple(None if b is None else Path(b) for b in self.baseline_steps)
        if base and len(base) != len(exps):
            raise ParameterError(
                f"baseline_steps needs one entry per experiment ({len(exps)}), got {len(base)}"
            )
        object.__setattr__(self, "baseline_steps", base)
        if not isinstance(self.shorten, bool):
            raise ParameterError(f"shorten must be true or false, got {self.shorten!r}")
        if self.shorten:
            check_shorten(self)

    def baseline_for(self, i: int) -> Path | None:
        return self.baseline_steps[i] if self.baseline_steps else None


def check_shorten(config: CampaignConfig) -> None:
    """Refuse ``shorten`` where it cannot apply: a robust box, or another objective."""
    robust = config.robust_tau_s is not None or config.robust_dt0_c is not None
    other = sorted({s.objective for s in config.experiments} - {"shortest"})
    if robust or other:
        raise ParameterError(
            "shorten (--shorten, or shorten = true in [settings]) applies to the shortest "
            "objective planned for one model: "
            + ("remove the [robust] table" if robust else f"objective {', '.join(other)}")
            + " or drop shorten"
        )


def default_campaign() -> CampaignConfig:
    """The paper's four experiments W1..W4 with the default model, limits and settings.

    Experiment W1 is compared with the paper-like baseline :data:`PAPER_BASELINE_EXP1`
    (``baseline_exp1_steps.csv``, shipped in the package).
    """
    exps = tuple(ExperimentSpec(n, wl, wh, al, ah) for n, wl, wh, al, ah in PAPER_REGIONS_C)
    return CampaignConfig(experiments=exps, baseline_steps=(PAPER_BASELINE_EXP1, None, None, None))


# ---------------------------------------------------------------------------------------
# TOML
# ---------------------------------------------------------------------------------------
def _where(path: Path | str, table: str, key: str | None = None) -> str:
    return f"{path}: [{table}]" + (f" {key}" if key else "")


def _check_keys(table: dict, allowed: Sequence[str], where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")


def _value(value: Any, key: str, where: str) -> Any:
    """Type-check one TOML value for the field ``key`` (ints are fine for floats)."""
    if key in _STR_KEYS:
        if not isinstance(value, str):
            raise ParameterError(f"{where} {key} must be a string, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(f"{where} {key} must be a number, got {value!r}")
    if key in _INT_KEYS:
        if float(value) != int(value):
            raise ParameterError(f"{where} {key} must be a whole number, got {value!r}")
        return int(value)
    return float(value)


def _table(doc: dict, name: str, path: Path) -> dict:
    t = doc.get(name, {})
    if not isinstance(t, dict):
        raise ParameterError(f"{path}: {name} must be a table [{name}], got {t!r}")
    return t


def _pair(value: Any, where: str) -> tuple[float, float]:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or any(isinstance(x, bool) or not isinstance(x, int | float) for x in value)
    ):
        raise ParameterError(f"{where} must be [LO, HI] (two numbers), got {value!r}")
    return float(value[0]), float(value[1])


def _wrap(where: str, build: Callable[[], Any]) -> Any:
    try:
        return build()
    except SchedsynError as exc:
        raise ParameterError(f"{where}: {exc}") from None


def campaign_from_dict(doc: dict, path: Path | str = "<config>") -> CampaignConfig:
    """Build a :class:`CampaignConfig` from a parsed TOML document (see module doc)."""
    path = Path(path)
    _check_keys(
        doc,
        ("model", "chamber", "limits", "settings", "robust", "experiment", "export", "sheet"),
        str(path),
    )
    model = _table(doc, "model", path)
    _check_keys(model, ("tau_s", "dt0_c"), _where(path, "model"))
    params = _wrap(
        _where(path, "model"),
        lambda: ThermalParams(**{k: _value(v, k, _where(path, "model")) for k, v in model.items()}),
    )
    preset = _chamber_table(_table(doc, "chamber", path), _where(path, "chamber"))
    lim = _table(doc, "limits", path)
    lim_keys = [f.name for f in dataclasses.fields(Limits)]
    _check_keys(lim, lim_keys, _where(path, "limits"))
    # precedence: Limits' defaults < the chamber preset < the [limits] keys
    base_limits = {} if preset is None else {f: getattr(preset, f) for f in LIMIT_FIELDS}
    limits = _wrap(
        _where(path, "limits"),
        lambda: Limits(
            **{
                **base_limits,
                **{k: _value(v, k, _where(path, "limits")) for k, v in lim.items()},
            }
        ),
    )
    settings = dict(_table(doc, "settings", path))
    _check_keys(settings, (*_SETTING_KEYS, "shorten"), _where(path, "settings"))
    shorten = settings.pop("shorten", False)
    if not isinstance(shorten, bool):
        raise ParameterError(
            f"{_where(path, 'settings', 'shorten')} must be true or false, got {shorten!r}"
        )
    settings = {k: _value(v, k, _where(path, "settings")) for k, v in settings.items()}
    if preset is not None:  # the preset's step limit, unless [settings] names one
        settings = {"max_steps": preset.max_steps, **settings}
    robust = _table(doc, "robust", path)
    _check_keys(robust, ("tau_s", "dt0_c"), _where(path, "robust"))
    box = {k: _pair(v, _where(path, "robust", k)) for k, v in robust.items()}
    exports = _export_table(_table(doc, "export", path), _where(path, "export"))
    sheet = _sheet_table(_table(doc, "sheet", path), _where(path, "sheet"))

    raw = doc.get("experiment")
    if raw is None:
        raise ParameterError(
            f"{path}: no experiment; add at least one [[experiment]] table "
            "with name, working_lo_c, working_hi_c, approx_lo_c, approx_hi_c"
        )
    if not isinstance(raw, list) or not all(isinstance(e, dict) for e in raw) or not raw:
        raise ParameterError(f"{path}: experiment must be an array of tables [[experiment]]")
    specs: list[ExperimentSpec] = []
    baselines: list[Path | None] = []
    for i, exp in enumerate(raw, start=1):
        where = f"{path}: [[experiment]] #{i}" + (
            f" ({exp['name']})" if isinstance(exp.get("name"), str) else ""
        )
        _check_keys(exp, (*_REGION_KEYS, *_SETTING_KEYS, "baseline_steps"), where)
        missing = [k for k in _REGION_KEYS if k not in exp]
        if missing:
            raise ParameterError(f"{where}: missing key(s) {missing}")
        base = exp.get("baseline_steps")
        if base is not None:
            if not isinstance(base, str) or not base:
                raise ParameterError(f"{where} baseline_steps must be a file name, got {base!r}")
            base_path = Path(base)
            if not base_path.is_absolute():
                base_path = path.resolve().parent / base_path
            if not base_path.is_file() and base_path.name == base and _shipped(base):
                # a copy of the shipped campaign file moved elsewhere names the shipped
                # baseline beside it (red team: the README's "a copy of
                # data/paper_campaign.toml" failed anywhere but in data/)
                base_path = package_data(base)
            if not base_path.is_file():
                raise ParameterError(
                    f"{where} baseline_steps: {base_path} does not exist (a relative path is "
                    f"read from the campaign file's folder, {path.resolve().parent}); copy "
                    "the table beside the campaign file, give its absolute path, or drop "
                    "baseline_steps"
                )
            baselines.append(base_path)
        else:
            baselines.append(None)
        kw = {
            **settings,
            **{k: _value(v, k, where) for k, v in exp.items() if k != "baseline_steps"},
        }
        specs.append(_wrap(where, partial(ExperimentSpec, **kw)))
    return _wrap(
        str(path),
        lambda: CampaignConfig(
            experiments=tuple(specs),
            params=params,
            limits=limits,
            robust_tau_s=box.get("tau_s"),
            robust_dt0_c=box.get("dt0_c"),
            baseline_steps=tuple(baselines) if any(b is not None for b in baselines) else (),
            exports=exports,
            sheet=sheet,
            shorten=shorten,
        ),
    )


def _chamber_table(t: dict, where: str) -> ChamberPreset | None:
    """``[chamber]``: ``preset = "NAME"`` (see :mod:`schedsyn.chambers`), or nothing."""
    if not t:
        return None
    _check_keys(t, ("preset",), where)
    name = t.get("preset")
    if not isinstance(name, str):
        raise ParameterError(
            f'{where} preset must be a preset name (a string, e.g. "binder-mk-56"), got {name!r}'
        )
    return _wrap(where, partial(chamber_preset, name))


def _export_table(t: dict, where: str) -> tuple[ExportSettings, ...]:
    """``[export]``: ``controller`` (a name or a list of names) and the export options."""
    if not t:
        return ()
    _check_keys(t, ("controller", "first_programme", "max_steps", "programmes", "end_mode"), where)
    ctl = t.get("controller")
    names = [ctl] if isinstance(ctl, str) else ctl
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ParameterError(
            f"{where} controller must be a controller name or a list of names, got {ctl!r}"
        )
    kw: dict[str, Any] = {}
    for key in ("first_programme", "max_steps", "programmes"):
        if key in t:
            v = t[key]
            if isinstance(v, bool) or not isinstance(v, int):
                raise ParameterError(f"{where} {key} must be a whole number, got {v!r}")
            kw[key] = v
    if "end_mode" in t:
        if not isinstance(t["end_mode"], str):
            raise ParameterError(f"{where} end_mode must be a string, got {t['end_mode']!r}")
        kw["end_mode"] = t["end_mode"]
    return tuple(_wrap(where, partial(ExportSettings, controller=n, **kw)) for n in names)


def _sheet_table(t: dict, where: str) -> SheetSettings:
    """``[sheet]``: start (a string or a TOML date-time), interval and band options."""
    _check_keys(t, ("start", "interval_min", "band_tau_rel", "band_dt0_c", "n_tau"), where)
    kw: dict[str, Any] = {}
    if "start" in t:
        v = t["start"]
        if isinstance(v, str):
            kw["start"] = _wrap(where, partial(parse_start, v))
        elif hasattr(v, "hour") and hasattr(v, "year"):  # a TOML local date-time
            kw["start"] = v.replace(tzinfo=None)
        else:
            raise ParameterError(
                f'{where} start must be a date and time like "2026-11-24 08:00", got {v!r}'
            )
    for key in ("interval_min", "band_tau_rel", "band_dt0_c"):
        if key in t:
            v = t[key]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise ParameterError(f"{where} {key} must be a number, got {v!r}")
            kw[key] = float(v)
    if "n_tau" in t:
        v = t["n_tau"]
        if isinstance(v, bool) or not isinstance(v, int):
            raise ParameterError(f"{where} n_tau must be a whole number, got {v!r}")
        kw["n_tau"] = v
    return _wrap(where, partial(SheetSettings, **kw))


def load_campaign(path: Path | str) -> CampaignConfig:
    """Read a campaign TOML file; errors name the file, the table and the key."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"campaign file {path} does not exist or is not a file")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{path} is not valid TOML ({exc})") from None
    return campaign_from_dict(doc, path)


# ---------------------------------------------------------------------------------------
# planning
# ---------------------------------------------------------------------------------------
def stderr_progress(message: str) -> None:
    """A picklable progress callable: one line on stderr (timestamped when stderr is a
    file or pipe; see :class:`schedsyn.progress.Progress`)."""
    Progress()(message)


@dataclass(frozen=True, slots=True)
class _PlanJob:
    spec: ExperimentSpec
    params: ThermalParams
    limits: Limits
    robust_tau_s: tuple[float, float] | None
    robust_dt0_c: tuple[float, float] | None
    shorten: bool = False
    end_soak: bool = False


@dataclass(frozen=True, slots=True)
class Infeasible:
    """An experiment nothing could be planned for: the planner's message, best coverage."""

    message: str
    best_coverage: float

    def __str__(self) -> str:
        return self.message


def _plan_job(job: _PlanJob, progress: Callable[[str], None] | None) -> Plan | Infeasible:
    """Plan one experiment; an infeasible request is returned, not raised (the others go on).

    (An exception's extra attributes do not survive pickling back from a worker, hence
    :class:`Infeasible`.)
    """
    tic = time.perf_counter()
    name = job.spec.name

    def say(msg: str) -> None:  # which experiment, solver time so far
        if progress is not None:
            progress(f"{name} [{time.perf_counter() - tic:6.1f} s] {msg}")

    say("planning")
    try:
        plan = plan_experiment(
            job.spec,
            job.params,
            job.limits,
            robust_tau_s=job.robust_tau_s,
            robust_dt0_c=job.robust_dt0_c,
            progress=say,
            shorten=job.shorten,
            end_soak=job.end_soak,
        )
    except InfeasiblePlanError as exc:
        say(f"infeasible: {exc}")
        best = exc.best_coverage if exc.best_coverage is not None else 0.0
        return Infeasible(str(exc), float(best))
    say(f"done: {plan.status}, coverage {plan.coverage.coverage:.0%}, {plan.duration_min:g} min")
    return plan


def _baseline_row(
    path: Path | None, spec: ExperimentSpec, params: ThermalParams, limits: Limits
) -> dict:
    """Coverage of a paper-like step table by dense simulation (NaN/'none' without one)."""
    if path is None:
        return {
            "baseline": "none",
            "baseline_duration_min": np.nan,
            "baseline_steps": np.nan,
            "baseline_coverage": np.nan,
            "baseline_min_levels": np.nan,
            "baseline_coverage_delta_0p1": np.nan,
            "baseline_d_efficiency_pct": np.nan,
            "baseline_i_efficiency_pct": np.nan,
        }
    prog = read_steps(path)
    traj = simulate(prog, params, t0_c=limits.t_init_c)
    rep = coverage_report(
        traj.t_c, traj.g_c_per_min, spec.grid, spec.levels_required, spec.delta_c_per_min
    )
    rep01 = coverage_report(traj.t_c, traj.g_c_per_min, spec.grid, spec.levels_required, 0.1)
    design = _design_columns(
        lambda: programme_design(
            prog,
            DesignSpace(
                spec.working_lo_c,
                spec.working_hi_c,
                spec.approx_lo_c,
                spec.approx_hi_c,
                params,
                limits,
                spec.max_cool_c_per_min,
                spec.max_heat_c_per_min,
            ),
        ),
        "baseline_",
    )
    return {
        "baseline": Path(path).name,
        "baseline_duration_min": prog.total_min,
        "baseline_steps": prog.n_segments,
        "baseline_coverage": rep.coverage,
        "baseline_min_levels": rep.min_levels,
        "baseline_coverage_delta_0p1": rep01.coverage,
        **design,
    }


def _design_columns(report, prefix: str = "") -> dict:
    """D- and I-efficiency (percent) of a plan's samples for the full drift model
    (:mod:`schedsyn.design`); NaN where the design space cannot be built."""
    try:
        r = report()
    except SchedsynError:
        return {f"{prefix}d_efficiency_pct": np.nan, f"{prefix}i_efficiency_pct": np.nan}
    return {
        f"{prefix}d_efficiency_pct": r.d_efficiency_pct,
        f"{prefix}i_efficiency_pct": r.i_efficiency_pct,
    }


SUMMARY_COLUMNS = (
    "experiment",
    "working_min_c",
    "working_max_c",
    "duration_min",
    "duration_lower_bound_min",
    "gap_to_bound_min",
    "steps",
    "coverage",
    "min_levels",
    "solve_s",
    "coverage_delta_0p1",
    "complete",
    "status",
    "d_efficiency_pct",
    "i_efficiency_pct",
    "informative_price_min",
    "information_factor",
    "baseline",
    "baseline_duration_min",
    "baseline_steps",
    "baseline_coverage",
    "baseline_min_levels",
    "baseline_coverage_delta_0p1",
    "baseline_d_efficiency_pct",
    "baseline_i_efficiency_pct",
)


@dataclass(frozen=True, slots=True)
class CampaignResult:
    """The plans of a campaign (``None`` where a request was infeasible) and baselines.

    ``errors[i]`` is the message of an infeasible experiment ``i`` (empty otherwise).
    """

    config: CampaignConfig
    plans: tuple[Plan | None, ...]
    errors: tuple[str, ...]
    baselines: tuple[dict, ...]
    wall_s: float

    @property
    def complete(self) -> bool:
        """Every experiment planned and complete (by the independent check)."""
        return all(p is not None and p.complete for p in self.plans)

    def summary_frame(self) -> pd.DataFrame:
        """One row per experiment: the plan's figures next to the baseline's."""
        rows = []
        for spec, plan, base in zip(
            self.config.experiments, self.plans, self.baselines, strict=True
        ):
            if plan is not None:
                s = plan.to_summary_dict()
                row = {
                    k: s[k]
                    for k in (
                        "experiment",
                        "working_min_c",
                        "working_max_c",
                        "duration_min",
                        "duration_lower_bound_min",
                        "gap_to_bound_min",
                        "steps",
                        "coverage",
                        "min_levels",
                        "solve_s",
                        "coverage_delta_0p1",
                        "complete",
                        "informative_price_min",
                        "information_factor",
                    )
                }
                row["status"] = plan.status
                row.update(_design_columns(lambda plan=plan: plan_design(plan)))
            else:
                row = {
                    "experiment": spec.name,
                    "working_min_c": spec.working_lo_c,
                    "working_max_c": spec.working_hi_c,
                    "duration_min": np.nan,
                    "duration_lower_bound_min": np.nan,
                    "gap_to_bound_min": np.nan,
                    "steps": np.nan,
                    "coverage": 0.0,
                    "min_levels": 0,
                    "solve_s": np.nan,
                    "coverage_delta_0p1": 0.0,
                    "complete": False,
                    "status": "infeasible",
                    "d_efficiency_pct": np.nan,
                    "i_efficiency_pct": np.nan,
                }
            row.update(base)
            rows.append(row)
        return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))

    to_frame = summary_frame


def plan_campaign(
    config: CampaignConfig,
    progress: Callable[[str], None] | None = None,
    backend: Any = "local",
    *,
    workers: int | None = None,
    shorten: bool = False,
    end_soak: bool = False,
) -> CampaignResult:
    """Plan every experiment of ``config`` (in parallel on ``backend``, see ``run_map``).

    Parameters
    ----------
    config : CampaignConfig
    progress : callable(str), optional
        Receives lines like ``"W1 [  12.3 s] structure found: 480 min"`` (experiment,
        solver time so far, message). With the ``"local"`` backend it runs in the worker
        processes, so it must be picklable (a module-level function such as
        :func:`stderr_progress`). A tqdm bar on stderr counts finished experiments.
    backend : "local", "serial", Dask address or client
        Where to plan (default: a process pool over this machine's cores).
    workers : int, optional
        Size of the local pool.
    shorten : bool
        Give each complete plan to the timetable stage for a shorter one
        (:func:`~schedsyn.planner.plan_experiment`'s ``shorten``; 1-2 min more each);
        also when ``config.shorten``.
    end_soak : bool
        The tables will end with a soak (``--end-soak``): an ``informative`` plan ends
        settled where it can (``plan_experiment``'s ``end_soak``).

    Returns
    -------
    CampaignResult
        An infeasible experiment does not stop the others: its plan is ``None`` and its
        message is in ``errors``.
    """
    tic = time.perf_counter()
    shorten = shorten or config.shorten
    if shorten:
        check_shorten(config)
    jobs = [
        _PlanJob(
            s,
            config.params,
            config.limits,
            config.robust_tau_s,
            config.robust_dt0_c,
            shorten,
            end_soak,
        )
        for s in config.experiments
    ]
    # longest first, so that the pool is not left waiting on one long experiment at the end
    order = sorted(range(len(jobs)), key=lambda i: -planning_effort(jobs[i].spec, jobs[i].limits))
    done = run_map(
        partial(_plan_job, progress=progress),
        [jobs[i] for i in order],
        backend,
        workers=workers,
        progress=progress is not None,
        desc="experiments",
    )
    out = [None] * len(jobs)
    for k, i in enumerate(order):
        out[i] = done[k]
    plans = tuple(p if isinstance(p, Plan) else None for p in out)
    errors = tuple("" if isinstance(p, Plan) else str(p) for p in out)
    baselines = tuple(
        _baseline_row(config.baseline_for(i), s, config.params, config.limits)
        for i, s in enumerate(config.experiments)
    )
    return CampaignResult(config, plans, errors, baselines, time.perf_counter() - tic)


# ---------------------------------------------------------------------------------------
# what chamber do I need?
# ---------------------------------------------------------------------------------------
CHAMBER_COLUMNS = (
    "chamber_min_c",
    "chamber_max_c",
    "coverage",
    "coverage_delta_0p1",
    "min_levels",
    "duration_min",
    "steps",
    "complete",
    "status",
    "notes",
)


@dataclass(frozen=True, slots=True)
class _ChamberJob:
    spec: ExperimentSpec
    params: ThermalParams
    limits: Limits
    robust_tau_s: tuple[float, float] | None
    robust_dt0_c: tuple[float, float] | None


def _chamber_job(job: _ChamberJob, progress) -> Plan | Infeasible:
    tag = f"{job.spec.name} floor {job.limits.chamber_min_c:g} ceiling {job.limits.chamber_max_c:g}"
    return _plan_job(
        _PlanJob(job.spec, job.params, job.limits, job.robust_tau_s, job.robust_dt0_c),
        None if progress is None else partial(_tagged, progress, tag),
    )


def _tagged(progress, tag: str, msg: str) -> None:
    progress(f"{tag}: {msg}")


def chamber_plans(
    spec: ExperimentSpec,
    floors_c: Sequence[float] | None = None,
    ceilings_c: Sequence[float] | None = None,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    robust_tau_s: tuple[float, float] | None = None,
    robust_dt0_c: tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    backend: Any = "local",
    workers: int | None = None,
) -> tuple[list[tuple[float, float]], list[Plan | Infeasible]]:
    """Plan ``spec`` for every (floor, ceiling) pair; see :func:`chamber_requirement`."""
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    floors = [limits.chamber_min_c] if not floors_c else [float(x) for x in floors_c]
    ceilings = [limits.chamber_max_c] if not ceilings_c else [float(x) for x in ceilings_c]
    pairs = [(f, c) for f in floors for c in ceilings]
    jobs = []
    for f, c in pairs:
        try:
            lim = dataclasses.replace(limits, chamber_min_c=f, chamber_max_c=c)
        except ParameterError as exc:
            raise ParameterError(f"chamber floor {f:g} / ceiling {c:g} °C: {exc}") from None
        jobs.append(_ChamberJob(spec, params, lim, robust_tau_s, robust_dt0_c))
    out = run_map(
        partial(_chamber_job, progress=progress),
        jobs,
        backend,
        workers=workers,
        progress=progress is not None,
        desc="chambers",
    )
    return pairs, out


def chamber_frame(pairs, results) -> pd.DataFrame:
    """The table of :func:`chamber_requirement` from :func:`chamber_plans`' output."""
    rows = []
    for (f, c), r in zip(pairs, results, strict=True):
        if isinstance(r, Plan):
            rows.append(
                {
                    "chamber_min_c": f,
                    "chamber_max_c": c,
                    "coverage": r.coverage.coverage,
                    "coverage_delta_0p1": r.coverage_0p1.coverage,
                    "min_levels": r.coverage.min_levels,
                    "duration_min": r.duration_min,
                    "steps": r.steps,
                    "complete": r.complete,
                    "status": r.status,
                    "notes": " | ".join(r.notes),
                }
            )
        else:
            rows.append(
                {
                    "chamber_min_c": f,
                    "chamber_max_c": c,
                    "coverage": r.best_coverage,
                    "coverage_delta_0p1": np.nan,
                    "min_levels": 0,
                    "duration_min": np.nan,
                    "duration_lower_bound_min": np.nan,
                    "gap_to_bound_min": np.nan,
                    "steps": np.nan,
                    "complete": False,
                    "status": "infeasible",
                    "notes": str(r),
                }
            )
    return pd.DataFrame(rows, columns=list(CHAMBER_COLUMNS))


def chamber_requirement(
    spec: ExperimentSpec,
    floors_c: Sequence[float] | None = None,
    ceilings_c: Sequence[float] | None = None,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    robust_tau_s: tuple[float, float] | None = None,
    robust_dt0_c: tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    backend: Any = "local",
    workers: int | None = None,
) -> pd.DataFrame:
    """Coverage as a function of the chamber floor and ceiling ("what chamber do I need?").

    Plans ``spec`` once for every pair of ``floors_c`` x ``ceilings_c`` (degC; a missing
    list keeps the value of ``limits``) and reports, per pair, the coverage of the
    exported table (independent dense check) at ``delta`` and at 0.1 degC/min, the
    fewest distinct levels of any bin, the duration, the step count and whether the plan
    is complete. An infeasible pair is a row with status ``infeasible`` and its message.

    Near the cold end the floor bounds the cooling gradient, g = (Tk_min + dT0 - T)/tau,
    so coverage of a region near -50 degC grows as the floor is lowered.
    """
    pairs, results = chamber_plans(
        spec,
        floors_c,
        ceilings_c,
        params,
        limits,
        robust_tau_s=robust_tau_s,
        robust_dt0_c=robust_dt0_c,
        progress=progress,
        backend=backend,
        workers=workers,
    )
    return chamber_frame(pairs, results)
