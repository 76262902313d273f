"""Named chamber presets: rates, floor, ceiling and the controller's step limit.

A preset fills the chamber fields of :class:`~schedsyn.params.Limits`
(``rate_min_c_per_min``, ``rate_max_c_per_min``, ``chamber_min_c``, ``chamber_max_c``)
and the step limit of a plan (``ExperimentSpec.max_steps``: the steps one programme of
the chamber's controller holds, so that a plan runs as one programme). The device limits,
the duration and the start/end temperatures are the experiment's, not the chamber's, and a
preset leaves them alone. Explicit settings always override a preset
(``schedsyn plan --chamber NAME --chamber-min-c -60``; in a campaign file, ``[limits]``
and ``[settings] max_steps`` override ``[chamber] preset``).

Every figure names its source (:attr:`ChamberPreset.sources`); a figure we could not find
in a public datasheet is marked as an **assumption**: check it against your chamber's
datasheet, and prefer rates you measured with your fixture inside. Datasheet rates are
means per IEC 60068-3-5 over the range without its outer 10 % at each end, in an empty
chamber (wkm-michel.de, "Temperaturänderungsgeschwindigkeit nach DIN EN IEC 60068-3-5";
cts-umweltsimulation.at, "Temperatur"): a loaded chamber following a linear ramp is
slower, especially cooling near its floor.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import pandas as pd

from .errors import ParameterError
from .params import Limits, real_number

#: The fields of :class:`~schedsyn.params.Limits` a preset sets.
LIMIT_FIELDS = ("rate_min_c_per_min", "rate_max_c_per_min", "chamber_min_c", "chamber_max_c")
#: Every figure of a preset, in the order the listing shows them.
FIGURES = (*LIMIT_FIELDS, "max_steps")
#: A source text starting with this marks the figure as an assumption.
ASSUMPTION = "assumption"


@dataclass(frozen=True, slots=True)
class ChamberPreset:
    """One chamber model: its limits, its controller and where each figure comes from.

    Parameters
    ----------
    name : str
        Preset name (``--chamber NAME``), lower case.
    title : str
        Maker and model, for people.
    rate_min_c_per_min, rate_max_c_per_min : float
        Fastest cooling (< 0) and heating (> 0) ramp the chamber follows, degC/min.
    chamber_min_c, chamber_max_c : float
        Chamber air floor and ceiling, degC.
    controller : str
        The exporter of its controller (:data:`schedsyn.export.CONTROLLER_KEYS`);
        ``"csv"`` where no programme format is published (typed in by hand).
    max_steps : int
        Steps of the step table that fit in one programme of that controller (the
        segments the exporter reserves, e.g. Binder's closing 1-s segment, taken off).
    sources : tuple of (figure, source)
        One entry per figure of :data:`FIGURES`; a source starting with ``"assumption"``
        marks a figure not found in a public datasheet.
    """

    name: str
    title: str
    rate_min_c_per_min: float
    rate_max_c_per_min: float
    chamber_min_c: float
    chamber_max_c: float
    controller: str
    max_steps: int
    sources: tuple[tuple[str, str], ...]

    def __post_init__(self) -> None:
        for f in LIMIT_FIELDS:
            object.__setattr__(self, f, real_number(f, getattr(self, f)))
        self.limits()  # the figures make valid limits (rates around 0, floor < ceiling)
        steps = self.max_steps
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
            raise ParameterError(
                f"chamber preset {self.name}: max_steps must be a whole number >= 2"
            )
        missing = [f for f in FIGURES if f not in dict(self.sources)]
        if missing:
            raise ParameterError(f"chamber preset {self.name}: no source for {missing}")

    def limits(self, base: Limits | None = None) -> Limits:
        """``base`` (default :class:`Limits`) with this chamber's rates, floor and ceiling."""
        base = Limits() if base is None else base
        try:
            return dataclasses.replace(base, **{f: getattr(self, f) for f in LIMIT_FIELDS})
        except ParameterError as exc:
            raise ParameterError(f"chamber preset {self.name}: {exc}") from None

    def source(self, figure: str) -> str:
        return dict(self.sources)[figure]

    @property
    def assumed(self) -> tuple[str, ...]:
        """The figures that are assumptions (no public datasheet found)."""
        return tuple(f for f, s in self.sources if s.startswith(ASSUMPTION))

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "title": self.title,
            **{f: getattr(self, f) for f in FIGURES},
            "controller": self.controller,
            "assumed": list(self.assumed),
            "sources": dict(self.sources),
        }


_PAPER = (
    "the reference paper (planning calibration tests of angular-rate sensors): the "
    "ESPEC SET-Z-032U ramps at -1 <= U <= +3 °C/min"
)
_SCHEDSYN_DEFAULT_FLOOR = (
    "assumption: schedsyn's default chamber (Limits), a cascade-refrigerated chamber; "
    "ESPEC's FAQ (espec.com/na/chamber_faq/answer/low_temp_limit) puts cascade "
    "refrigeration at about -65 .. -73 °C; the paper gives no floor"
)
_P300_STEPS = (
    "assumption: 99 steps per ESPEC P-300 programme as in schedsyn.controllers.espec "
    "(ChamberConnectLibrary p300.py encodes no step limit); the paper names no controller"
)
_BINDER_STEPS = (
    "auger-prime-sde/ess binder.py (Binder_MKFT115_MB1/MB2: NSEG = 100 segments per "
    "programme, 'Max. 100 segments allowed'), less the closing 1-s segment the "
    "binder-mb exporter adds (schedsyn.controllers.binder)"
)
_NO_UPLOAD_STEPS = (
    "assumption: no public programme format or step limit (SIMSERV, IzaakWN/"
    "ClimateChamberMonitor commands.py, starts stored programmes only); schedsyn's default 80"
)

#: The presets, by name. Each figure's source is beside it.
PRESETS: dict[str, ChamberPreset] = {
    p.name: p
    for p in (
        ChamberPreset(
            name="espec-set-z-032u",
            title="ESPEC SET-Z-032U (the paper's chamber)",
            rate_min_c_per_min=-1.0,  # the paper
            rate_max_c_per_min=3.0,  # the paper
            chamber_min_c=-70.0,  # assumption (schedsyn's default)
            chamber_max_c=80.0,  # assumption (schedsyn's default)
            controller="espec-p300",  # assumption: the paper names no controller
            max_steps=99,  # assumption: P-300 figure of schedsyn.controllers.espec
            sources=(
                ("rate_min_c_per_min", _PAPER),
                ("rate_max_c_per_min", _PAPER),
                ("chamber_min_c", _SCHEDSYN_DEFAULT_FLOOR),
                (
                    "chamber_max_c",
                    "assumption: schedsyn's default chamber (Limits); the paper gives no "
                    "ceiling (its range ends at +60 °C)",
                ),
                ("max_steps", _P300_STEPS),
            ),
        ),
        ChamberPreset(
            name="espec-sh-242",
            title="ESPEC SH-242 bench-top temperature and humidity chamber",
            rate_min_c_per_min=-1.0,  # assumption
            rate_max_c_per_min=2.0,  # assumption
            chamber_min_c=-40.0,  # ESPEC catalogue figure (not verified here)
            chamber_max_c=150.0,  # ESPEC catalogue figure (not verified here)
            controller="csv",  # its own bench-top controller: typed in by hand
            max_steps=80,  # assumption
            sources=(
                (
                    "rate_min_c_per_min",
                    "assumption: single-stage bench-top refrigeration; ESPEC's FAQ "
                    "(low_temp_limit): single-stage chambers reach -35 .. -40 °C and 'going "
                    "to lower temperatures becomes a slow process'",
                ),
                ("rate_max_c_per_min", "assumption: no public rate figure found"),
                (
                    "chamber_min_c",
                    "assumption: -40 °C as ESPEC lists for the SH-242 (datasheet not found "
                    "by our search: check yours); consistent with ESPEC's FAQ for "
                    "single-stage refrigeration (-35 .. -40 °C)",
                ),
                (
                    "chamber_max_c",
                    "assumption: +150 °C as ESPEC lists for the SH-242 (datasheet not found "
                    "by our search: check yours)",
                ),
                (
                    "max_steps",
                    "assumption: the bench-top controller's step limit was not found; "
                    "schedsyn's default 80",
                ),
            ),
        ),
        ChamberPreset(
            name="binder-mk-56",
            title="BINDER MK 56 alternating climate chamber (MB1/MB2 programme controller)",
            rate_min_c_per_min=-2.0,  # assumption
            rate_max_c_per_min=3.0,  # assumption
            chamber_min_c=-40.0,  # MK series floor (not verified here)
            chamber_max_c=180.0,  # MK series ceiling (not verified here)
            controller="binder-mb",  # BINDER MK (E5) operating manual: program control
            max_steps=99,  # 100 segments per programme (auger-prime-sde/ess binder.py)
            sources=(
                ("rate_min_c_per_min", "assumption: no public rate figure found"),
                ("rate_max_c_per_min", "assumption: no public rate figure found"),
                (
                    "chamber_min_c",
                    "assumption: -40 °C, the MK series floor (the MKT series goes deeper; "
                    "BINDER operating manual MK/MKT (E5), art. no. 7001-0364, lists MK 56 "
                    "among the MK chambers; its technical data were not found by our search)",
                ),
                (
                    "chamber_max_c",
                    "assumption: +180 °C, the MK series ceiling (technical data not found by "
                    "our search: check yours)",
                ),
                ("max_steps", _BINDER_STEPS),
            ),
        ),
        ChamberPreset(
            name="binder-mkt-115",
            title="BINDER MKT 115 alternating climate chamber with deep temperature (MB1/MB2)",
            rate_min_c_per_min=-2.0,  # assumption
            rate_max_c_per_min=3.0,  # assumption
            chamber_min_c=-70.0,  # MKT series floor (not verified here)
            chamber_max_c=180.0,  # MKT series ceiling (not verified here)
            controller="binder-mb",
            max_steps=99,  # 100 segments per programme (auger-prime-sde/ess binder.py)
            sources=(
                ("rate_min_c_per_min", "assumption: no public rate figure found"),
                ("rate_max_c_per_min", "assumption: no public rate figure found"),
                (
                    "chamber_min_c",
                    "assumption: -70 °C, the 'deep temperature' MKT series floor (BINDER "
                    "operating manual MK/MKT (E5), art. no. 7001-0364; technical data not "
                    "found by our search)",
                ),
                ("chamber_max_c", "assumption: +180 °C, the MKT series ceiling"),
                ("max_steps", _BINDER_STEPS),
            ),
        ),
        ChamberPreset(
            name="weiss-climeevent-c-340-40-3",
            title="Weiss Technik ClimeEvent C/340/40/3 climate chamber",
            rate_min_c_per_min=-3.0,  # the model code's rate, K/min
            rate_max_c_per_min=3.0,  # the model code's rate, K/min
            chamber_min_c=-40.0,  # the model code's floor
            chamber_max_c=180.0,  # assumption
            controller="csv",  # no public programme upload (SIMSERV)
            max_steps=80,  # assumption
            sources=(
                (
                    "rate_min_c_per_min",
                    "the model code C/<litres>/<floor>/<K/min>: 3 K/min, a mean per IEC "
                    "60068-3-5 in an empty chamber (wkm-michel.de): a loaded linear ramp is "
                    "slower; measure yours",
                ),
                ("rate_max_c_per_min", "the model code: 3 K/min (mean per IEC 60068-3-5)"),
                ("chamber_min_c", "the model code C/340/40/3: -40 °C"),
                (
                    "chamber_max_c",
                    "assumption: +180 °C, the usual ceiling of such chambers (hust.com.vn, "
                    "'How to choose temperature & humidity test chamber': makers set the "
                    "maximum at +150 .. +180 °C)",
                ),
                ("max_steps", _NO_UPLOAD_STEPS),
            ),
        ),
        ChamberPreset(
            name="votsch-vt3-7060",
            title="Vötsch VT³ 7060 temperature test chamber",
            rate_min_c_per_min=-2.0,  # assumption
            rate_max_c_per_min=3.0,  # assumption
            chamber_min_c=-70.0,  # the model code's floor
            chamber_max_c=180.0,  # assumption
            controller="csv",  # no public programme upload (SIMSERV)
            max_steps=80,  # assumption
            sources=(
                ("rate_min_c_per_min", "assumption: no public rate figure found"),
                ("rate_max_c_per_min", "assumption: no public rate figure found"),
                (
                    "chamber_min_c",
                    "the model code VT³ 7060: 7 = -70 °C floor (a listing of the Heraeus "
                    "Vötsch HT 4060 reads '-70 + 180'; check your datasheet)",
                ),
                (
                    "chamber_max_c",
                    "assumption: +180 °C (the same listing: '-70 + 180'; datasheet not "
                    "found by our search)",
                ),
                ("max_steps", _NO_UPLOAD_STEPS),
            ),
        ),
    )
}


def chamber_preset(name: str) -> ChamberPreset:
    """The preset called ``name`` (case and surrounding blanks ignored).

    Raises
    ------
    ParameterError
        Unknown name; the message lists the known ones.
    """
    if not isinstance(name, str):
        raise ParameterError(f"a chamber preset is named by a string, got {name!r}")
    key = name.strip().lower()
    if key not in PRESETS:
        raise ParameterError(
            f"unknown chamber preset {name!r}; choose one of {', '.join(PRESETS)} "
            "(schedsyn chambers lists them with their sources)"
        )
    return PRESETS[key]


def presets_frame() -> pd.DataFrame:
    """One row per preset: its figures, controller and which figures are assumptions."""
    rows = []
    for p in PRESETS.values():
        rows.append(
            {
                "name": p.name,
                "title": p.title,
                **{f: getattr(p, f) for f in FIGURES},
                "controller": p.controller,
                "assumed": " ".join(p.assumed) if p.assumed else "",
            }
        )
    return pd.DataFrame(rows)


def limits_with_preset(
    preset: ChamberPreset | str | None, base: Limits | None = None, **explicit: float | None
) -> Limits:
    """Limits from ``base`` (default :class:`Limits`), then the preset, then the explicit
    values that are not None (the precedence of ``--chamber`` and the options beside it)."""
    limits = Limits() if base is None else base
    if preset is not None:
        p = chamber_preset(preset) if isinstance(preset, str) else preset
        limits = p.limits(limits)
    given = {k: v for k, v in explicit.items() if v is not None}
    unknown = sorted(set(given) - {f.name for f in dataclasses.fields(Limits)})
    if unknown:
        raise ParameterError(f"unknown limit(s) {unknown}")
    return dataclasses.replace(limits, **given)
