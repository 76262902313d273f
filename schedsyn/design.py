"""How informative a plan is for the drift fit, before it is run.

The drift model is linear in its coefficients, ``drift = x(T, g)' c`` with ``x`` the terms
of :mod:`schedsyn.terms`. A run's samples ``(T_k, g_k)`` inside the approximation region
give the (per-sample) information matrix::

    M = (1/n) sum_k x_k x_k'          x_k = x(T_k, g_k) in coded variables

(with white drift noise sigma^2, ``cov(c_hat) = sigma^2 M^-1 / n``). The coded variables
map the approximation region ``[A_lo, A_hi]`` and the reachable gradients ``[G_lo, G_hi]``
(below) to [-1, 1]: ``u = (T - A_mid)/A_half``, ``v = (g - G_mid)/G_half``. Criteria:

* **D-efficiency** ``100 det(M)^(1/p)`` and **A-efficiency** ``100 p / tr(M^-1)`` (percent;
  pyDOE3's ``d_efficiency`` and ``a_efficiency``): 100 % for an orthogonal design with
  unit-variance columns, e.g. a two-level factorial for a linear model;
* **prediction variance** ``d(T, g) = x(T, g)' M^-1 x(T, g)`` over the working region and
  the reachable gradients (the map; units of ``sigma^2 / n``), its mean (the
  **I-criterion**, pyDOE3's ``i_optimality`` with the uniform moment matrix ``W`` of that
  region) and maximum (G);
* **I-efficiency** ``100 I* / I``, where ``I*`` is the I-criterion of the I-optimal
  approximate design on the reachable part of the approximation region (multiplicative
  algorithm, :func:`i_optimal_design`; 100 % = as good as any distribution of samples
  the chamber could reach).

All are per sample inside the approximation region; ``in_region_fraction`` says how much
of the run that is (a whole-run efficiency is the product: samples outside the region
carry no information for the fit over it).

**Reachable gradients** (:func:`reachable_gradients`): at temperature ``T`` the planning
model ``tau dT/dt + T = Tk + dT0``, ``dTk/dt = U`` bounds the gradient by

* the chamber air limits: ``(Tk_min + dT0 - T)/tau <= g <= (Tk_max + dT0 - T)/tau``;
* speeding up from rest at the far device limit at the full chamber rate ``U``: the
  distance is ``tau (-v - U ln(1 - v/U))`` for speed ``v``;
* stopping before the near device limit at the full reverse rate ``b``: the distance is
  ``tau (v - b ln(1 + v/b))``;
* the fastest cooling and heating gradients a plan uses (``max_cool_c_per_min``,
  ``max_heat_c_per_min``, by default those of the planner's ``ExperimentSpec``: 0.85 and
  1.0 degC/min; faster sweeps cost long turnarounds).

The planner's own bands keep inside these bounds (it uses 85-90 % of the rates and 92 %
of the chamber-limited gradient).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
import pandas as pd

from .errors import ParameterError
from .params import Limits, ThermalParams
from .programme import Programme
from .simulate import simulate
from .terms import monomials, parse_terms, term_set_name

#: Fastest cooling / heating gradient a plan uses, degC/min (the defaults of the planner's
#: ExperimentSpec: max_cool_c_per_min, max_heat_c_per_min; a test keeps them equal).
MAX_COOL_C_PER_MIN = 0.85
MAX_HEAT_C_PER_MIN = 1.0
#: Grid of the prediction-variance map and of the I-criterion's region, degC and degC/min.
MAP_T_STEP_C = 0.5
MAP_G_STEP_C_PER_MIN = 0.025
#: Candidate grid of the I-optimal design, degC and degC/min.
CANDIDATE_T_STEP_C = 1.0
CANDIDATE_G_STEP_C_PER_MIN = 0.05
#: The I-optimal design is found to within this relative accuracy of its criterion.
I_OPTIMAL_TOL = 0.005
#: A coded information matrix with a larger condition number counts as singular.
SINGULAR_COND = 1e12
#: Planned samples are taken every minute (the planner's sample spacing).
SAMPLE_MIN = 1.0
#: A run that stops this short of an end of the approximation region is said not to reach
#: it (the fit's bins there would be empty), degC.
REACH_TOL_C = 0.5


# -- reachable gradients ----------------------------------------------------------------
def _invert(dist, room: np.ndarray, v_max: float) -> np.ndarray:
    """Largest ``v`` in ``[0, v_max)`` with ``dist(v) <= room`` (``dist`` increasing)."""
    room = np.asarray(room, dtype=float)
    lo = np.zeros_like(room)
    hi = np.full_like(room, v_max)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = dist(mid) <= room
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return np.where(room > 0, lo, 0.0)


def _speed_up_distance(v: np.ndarray, rate: float, tau_min: float) -> np.ndarray:
    # from rest at full rate U: dv/dt = (U - v)/tau  =>  distance tau (-v - U ln(1 - v/U))
    return tau_min * (-v - rate * np.log1p(-np.minimum(v / rate, 1.0 - 1e-15)))


def _stop_distance(v: np.ndarray, rate: float, tau_min: float) -> np.ndarray:
    # reversing at full rate b: dv/dt = -(b + v)/tau  =>  distance tau (v - b ln(1 + v/b))
    return tau_min * (v - rate * np.log1p(v / rate))


def reachable_gradients(
    t_c: np.ndarray,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    max_cool_c_per_min: float = MAX_COOL_C_PER_MIN,
    max_heat_c_per_min: float = MAX_HEAT_C_PER_MIN,
) -> tuple[np.ndarray, np.ndarray]:
    """``(g_lo, g_hi)``: the gradients a run can have at each temperature (degC/min).

    See the module docstring: chamber air limits, speeding up from the far device limit
    and stopping before the near one at the full chamber rates, and the plan's fastest
    gradients. ``g_lo <= 0 <= g_hi``; both are 0 at and beyond the device limits.
    """
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    for name, v in (
        ("max_cool_c_per_min", max_cool_c_per_min),
        ("max_heat_c_per_min", max_heat_c_per_min),
    ):
        if not (math.isfinite(v) and v > 0):
            raise ParameterError(f"{name} must be > 0 °C/min, got {v!r}")
    t = np.asarray(t_c, dtype=float)
    tau = params.tau_min
    up, down = limits.rate_max_c_per_min, -limits.rate_min_c_per_min
    below = t - limits.device_min_c  # room below T (to the device floor)
    above = limits.device_max_c - t  # room above T
    big = 50.0
    heat = np.minimum.reduce(
        [
            np.full_like(t, max_heat_c_per_min),
            (limits.chamber_max_c + params.dt0_c - t) / tau,
            _invert(lambda v: _speed_up_distance(v, up, tau), below, up),
            _invert(lambda v: _stop_distance(v, down, tau), above, big),
        ]
    )
    cool = np.minimum.reduce(
        [
            np.full_like(t, max_cool_c_per_min),
            (t - limits.chamber_min_c - params.dt0_c) / tau,
            _invert(lambda v: _speed_up_distance(v, down, tau), above, down),
            _invert(lambda v: _stop_distance(v, up, tau), below, big),
        ]
    )
    return -np.maximum(cool, 0.0), np.maximum(heat, 0.0)


# -- the design space -------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class DesignSpace:
    """Where the drift model is fitted and where it must predict well.

    Parameters
    ----------
    working_lo_c, working_hi_c : float
        Working region, degC: the prediction-variance map and the I-criterion cover it.
    approx_lo_c, approx_hi_c : float
        Approximation region, degC (contains the working region): samples in it count,
        and it is coded to [-1, 1].
    params, limits : ThermalParams, Limits
        Device model and chamber limits that bound the reachable gradients.
    max_cool_c_per_min, max_heat_c_per_min : float
        Fastest cooling / heating gradient of a plan, degC/min (> 0).
    """

    working_lo_c: float
    working_hi_c: float
    approx_lo_c: float
    approx_hi_c: float
    params: ThermalParams = field(default_factory=ThermalParams)
    limits: Limits = field(default_factory=Limits)
    max_cool_c_per_min: float = MAX_COOL_C_PER_MIN
    max_heat_c_per_min: float = MAX_HEAT_C_PER_MIN

    def __post_init__(self) -> None:
        for name in ("working_lo_c", "working_hi_c", "approx_lo_c", "approx_hi_c"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{name} must be a finite number of °C, got {v!r}")
            object.__setattr__(self, name, float(v))
        if not self.working_lo_c < self.working_hi_c:
            raise ParameterError(
                f"the working region needs lo < hi, got {self.working_lo_c:g} .. "
                f"{self.working_hi_c:g} °C"
            )
        if not (self.approx_lo_c <= self.working_lo_c and self.working_hi_c <= self.approx_hi_c):
            raise ParameterError(
                f"the approximation region {self.approx_lo_c:g} .. {self.approx_hi_c:g} °C "
                f"must contain the working region {self.working_lo_c:g} .. "
                f"{self.working_hi_c:g} °C"
            )
        t = np.linspace(self.working_lo_c, self.working_hi_c, 41)
        g_lo, g_hi = reachable_gradients(
            t, self.params, self.limits, self.max_cool_c_per_min, self.max_heat_c_per_min
        )
        if not (np.any(g_hi > 0) and np.any(g_lo < 0)):
            raise ParameterError(
                f"no gradient is reachable in the working region {self.working_lo_c:g} .. "
                f"{self.working_hi_c:g} °C with the device limits "
                f"{self.limits.device_min_c:g} .. {self.limits.device_max_c:g} °C; keep the "
                "working region inside the device limits"
            )

    @staticmethod
    def default_approx(
        working_lo_c: float, working_hi_c: float, limits: Limits | None = None
    ) -> tuple[float, float]:
        """The paper's approximation region: 10 degC wider on each side, within the device
        limits (W1 = [-50, -30] gives [-52, -20]), but never inside the working region: a
        working region past the device limits is refused for that, by name
        (:func:`~schedsyn.planner.request.check_request`), not for an approximation
        region clipped inside it."""
        limits = Limits() if limits is None else limits
        return (
            min(max(working_lo_c - 10.0, limits.device_min_c), working_lo_c),
            max(min(working_hi_c + 10.0, limits.device_max_c), working_hi_c),
        )

    def gradient_band(self, t_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Reachable ``(g_lo, g_hi)`` at ``t_c`` (see :func:`reachable_gradients`)."""
        return reachable_gradients(
            t_c, self.params, self.limits, self.max_cool_c_per_min, self.max_heat_c_per_min
        )

    @property
    def gradient_range_c_per_min(self) -> tuple[float, float]:
        """Envelope ``(G_lo, G_hi)`` of the reachable gradients over the approximation region."""
        t = np.linspace(self.approx_lo_c, self.approx_hi_c, 401)
        lo, hi = self.gradient_band(t)
        return float(lo.min()), float(hi.max())

    def code(self, t_c: np.ndarray, g_c_per_min: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coded ``(u, v)`` in [-1, 1] over the approximation region and gradient envelope."""
        g_lo, g_hi = self.gradient_range_c_per_min
        u = (np.asarray(t_c, dtype=float) - 0.5 * (self.approx_lo_c + self.approx_hi_c)) / (
            0.5 * (self.approx_hi_c - self.approx_lo_c)
        )
        v = (np.asarray(g_c_per_min, dtype=float) - 0.5 * (g_lo + g_hi)) / (0.5 * (g_hi - g_lo))
        return u, v

    def grid(
        self, region: str = "working", t_step_c: float = MAP_T_STEP_C, g_step: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Points ``(T, g)`` on a regular grid inside the reachable band of a region.

        ``region`` is ``"working"`` or ``"approx"``; the grid is uniform in (T, g), so a
        plain mean over it is the mean over the region's area.
        """
        g_step = MAP_G_STEP_C_PER_MIN if g_step is None else g_step
        lo, hi = (
            (self.working_lo_c, self.working_hi_c)
            if region == "working"
            else (self.approx_lo_c, self.approx_hi_c)
        )
        n_t = max(int(round((hi - lo) / t_step_c)), 1)
        t = np.linspace(lo, hi, n_t + 1)
        g_lo, g_hi = self.gradient_range_c_per_min
        g = np.arange(math.floor(g_lo / g_step), math.ceil(g_hi / g_step) + 1) * g_step
        tt, gg = np.meshgrid(t, g, indexing="ij")
        b_lo, b_hi = self.gradient_band(t)
        inside = (gg >= b_lo[:, None] - 1e-12) & (gg <= b_hi[:, None] + 1e-12)
        return tt[inside], gg[inside]

    def to_dict(self) -> dict:
        g_lo, g_hi = self.gradient_range_c_per_min
        return {
            "working_lo_c": self.working_lo_c,
            "working_hi_c": self.working_hi_c,
            "approx_lo_c": self.approx_lo_c,
            "approx_hi_c": self.approx_hi_c,
            "g_lo_c_per_min": g_lo,
            "g_hi_c_per_min": g_hi,
            "max_cool_c_per_min": self.max_cool_c_per_min,
            "max_heat_c_per_min": self.max_heat_c_per_min,
        }


# -- criteria ---------------------------------------------------------------------------
def in_region(t_c: np.ndarray, g_c_per_min: np.ndarray, space: DesignSpace) -> np.ndarray:
    """The samples a fit over ``space`` uses: finite and inside the approximation region."""
    t = np.asarray(t_c, dtype=float)
    g = np.asarray(g_c_per_min, dtype=float)
    return np.isfinite(t) & np.isfinite(g) & (t >= space.approx_lo_c) & (t <= space.approx_hi_c)


def model_matrix(
    t_c: np.ndarray, g_c_per_min: np.ndarray, space: DesignSpace, terms: str | tuple = "full"
) -> np.ndarray:
    """Coded model matrix of the samples inside the approximation region (n_in x p)."""
    t = np.asarray(t_c, dtype=float)
    g = np.asarray(g_c_per_min, dtype=float)
    inside = in_region(t, g, space)
    u, v = space.code(t[inside], g[inside])
    return monomials(u, v, parse_terms(terms))


def information_matrix(
    t_c: np.ndarray, g_c_per_min: np.ndarray, space: DesignSpace, terms: str | tuple = "full"
) -> tuple[np.ndarray, int]:
    """``(M, n)``: per-sample information ``X'X/n`` of the ``n`` samples in the region.

    A pure function of the planned samples (the planner's objective can call it).
    """
    x = model_matrix(t_c, g_c_per_min, space, terms)
    n = x.shape[0]
    if n == 0:
        return np.zeros((x.shape[1], x.shape[1])), 0
    return x.T @ x / n, n


def log_det_information(
    t_c: np.ndarray, g_c_per_min: np.ndarray, space: DesignSpace, terms: str | tuple = "full"
) -> float:
    """``log det(sum_k x_k x_k')`` over the samples in the region (-inf if singular).

    Unnormalised: more informative samples always raise it (concave in the sample
    weights: the D-criterion an ``informative`` planner objective maximises).
    """
    m, n = information_matrix(t_c, g_c_per_min, space, terms)
    if n == 0:
        return -math.inf
    sign, logdet = np.linalg.slogdet(m * n)
    return float(logdet) if sign > 0 else -math.inf


def moment_matrix(space: DesignSpace, terms: tuple[str, ...]) -> np.ndarray:
    """Uniform moment matrix ``W = mean x x'`` over the working region's reachable grid."""
    t, g = space.grid("working")
    u, v = space.code(t, g)
    x = monomials(u, v, terms)
    return x.T @ x / x.shape[0]


def i_optimal_design(
    candidates: np.ndarray, weight_matrix: np.ndarray, tol: float = I_OPTIMAL_TOL
) -> tuple[float, np.ndarray]:
    """``(I*, w)``: the I-optimal approximate design on the candidate rows.

    Minimises ``I(w) = tr(W M(w)^-1)``, ``M(w) = sum_i w_i c_i c_i'`` over weights on the
    simplex by the multiplicative algorithm ``w_i <- w_i sqrt(d_i) / sum_j w_j sqrt(d_j)``,
    ``d_i = c_i' M^-1 W M^-1 c_i`` (monotone for this criterion; Yu 2010). It stops when
    ``max_i d_i <= (1 + tol) I(w)``: by convexity ``I* >= 2 I(w) - max_i d_i``, so the
    returned criterion is within ``tol`` of the optimum.
    """
    c = np.asarray(candidates, dtype=float)
    n, p = c.shape
    w = np.full(n, 1.0 / n)
    phi = math.inf
    for _ in range(20000):
        m = c.T @ (w[:, None] * c)
        m_inv = np.linalg.inv(m)
        b = m_inv @ weight_matrix @ m_inv
        d = np.einsum("ij,jk,ik->i", c, b, c)
        phi = float(np.trace(weight_matrix @ m_inv))
        if d.max() <= (1.0 + tol) * phi:
            return phi, w
        w = w * np.sqrt(np.maximum(d, 0.0))
        w /= w.sum()
    lower = 2.0 * phi - float(d.max())
    raise ParameterError(  # pragma: no cover - the algorithm converges on these grids
        f"the I-optimal design did not converge (criterion {phi:.4g}, bound {lower:.4g})"
    )


@lru_cache(maxsize=64)
def _i_optimum(space: DesignSpace, terms: tuple[str, ...]) -> float:
    t, g = space.grid("approx", CANDIDATE_T_STEP_C, CANDIDATE_G_STEP_C_PER_MIN)
    u, v = space.code(t, g)
    phi, _ = i_optimal_design(monomials(u, v, terms), moment_matrix(space, terms))
    return phi


@dataclass(frozen=True, slots=True)
class DesignReport:
    """Informativeness of a run's (planned) samples for the drift fit (module docstring).

    Attributes
    ----------
    space : DesignSpace
    terms : tuple of str
        The drift model's terms.
    n_samples, n_in_region : int
        Samples of the run, and those inside the approximation region.
    d_efficiency_pct, a_efficiency_pct : float
        D- and A-efficiency per sample in the region, percent (pyDOE3); 0 if singular.
    i_efficiency_pct : float
        ``100 I*/I``, percent of the I-optimal design's; 0 if singular.
    mean_variance, max_variance : float
        Mean (I-criterion) and largest prediction variance over the working region's
        reachable (T, g), in units of ``sigma^2 / n_in_region``; inf if singular.
    i_optimal_variance : float
        ``I*``, the mean prediction variance of the I-optimal design.
    log_det : float
        ``log det M`` of the per-sample information (-inf if singular).
    condition_number : float
        2-norm condition number of the coded model matrix.
    variance_map : DataFrame
        ``t_c, g_c_per_min, prediction_variance`` over the working region's grid.
    reached_lo_c, reached_hi_c : float
        The coldest and warmest sample inside the approximation region, degC (NaN if
        none): a fit over the region needs samples across it.
    """

    space: DesignSpace
    terms: tuple[str, ...]
    n_samples: int
    n_in_region: int
    d_efficiency_pct: float
    a_efficiency_pct: float
    i_efficiency_pct: float
    mean_variance: float
    max_variance: float
    i_optimal_variance: float
    log_det: float
    condition_number: float
    variance_map: pd.DataFrame
    reached_lo_c: float = math.nan
    reached_hi_c: float = math.nan

    @property
    def in_region_fraction(self) -> float:
        return self.n_in_region / self.n_samples if self.n_samples else 0.0

    @property
    def singular(self) -> bool:
        return not math.isfinite(self.mean_variance)

    def to_frame(self) -> pd.DataFrame:
        """The prediction-variance map."""
        return self.variance_map.copy()

    def to_summary_dict(self) -> dict:
        return {
            "terms": term_set_name(self.terms),
            **self.space.to_dict(),
            "n_samples": self.n_samples,
            "in_region_fraction": self.in_region_fraction,
            "d_efficiency_pct": self.d_efficiency_pct,
            "a_efficiency_pct": self.a_efficiency_pct,
            "i_efficiency_pct": self.i_efficiency_pct,
            "mean_prediction_variance": self.mean_variance,
            "max_prediction_variance": self.max_variance,
            "i_optimal_prediction_variance": self.i_optimal_variance,
            "log_det_information": self.log_det,
            "condition_number": self.condition_number,
            "reached_lo_c": self.reached_lo_c,
            "reached_hi_c": self.reached_hi_c,
        }

    def unreached(self) -> str:
        """What the run misses of the approximation region ("" when it reaches across
        it to within :data:`REACH_TOL_C`)."""
        lo, hi = self.space.approx_lo_c, self.space.approx_hi_c
        if not self.n_in_region:
            return f"the run never enters the approximation region {lo:g} .. {hi:g} °C"
        if self.reached_lo_c - lo <= REACH_TOL_C and hi - self.reached_hi_c <= REACH_TOL_C:
            return ""
        fit_lo = lo if self.reached_lo_c - lo <= REACH_TOL_C else math.ceil(self.reached_lo_c)
        fit_hi = hi if hi - self.reached_hi_c <= REACH_TOL_C else math.floor(self.reached_hi_c)
        return (
            f"the run reaches only {self.reached_lo_c:.1f} .. {self.reached_hi_c:.1f} °C of the "
            f"approximation region {lo:g} .. {hi:g} °C: fit over what it reaches (schedsyn fit "
            f"--region {fit_lo:g} {fit_hi:g})"
        )

    def summary(self) -> str:
        g_lo, g_hi = self.space.gradient_range_c_per_min
        head = (
            f"drift-fit design ({term_set_name(self.terms)} model over "
            f"{self.space.approx_lo_c:g} .. {self.space.approx_hi_c:g} °C, gradients "
            f"{g_lo:.2f} .. {g_hi:.2f} °C/min; {self.in_region_fraction:.0%} of the run in "
            "the region): "
        )
        missed = self.unreached()
        tail = f"; {missed}" if missed else ""
        if self.singular:
            return head + "singular: these samples cannot determine every term" + tail
        return (
            head
            + (
                f"D-efficiency {self.d_efficiency_pct:.1f} %, A-efficiency "
                f"{self.a_efficiency_pct:.2f} %, I-efficiency {self.i_efficiency_pct:.0f} % of the "
                f"I-optimal design; prediction variance over the working region mean "
                f"{self.mean_variance:.1f}, max {self.max_variance:.1f} (units of σ²/n)"
            )
            + tail
        )


def design_report(
    t_c: np.ndarray,
    g_c_per_min: np.ndarray,
    space: DesignSpace,
    terms: str | tuple = "full",
) -> DesignReport:
    """Information of samples ``(T, g)`` (equally spaced in time) for the drift fit.

    Parameters
    ----------
    t_c, g_c_per_min : arrays
        Internal temperature (degC) and gradient (degC/min) of the run's samples; samples
        outside the approximation region only count in ``n_samples``.
    space : DesignSpace
    terms : str or tuple
        Model terms (:func:`schedsyn.terms.parse_terms`; default the full cubic).
    """
    from pyDOE3.doe_optimal import a_efficiency, d_efficiency, i_optimality

    terms_t = parse_terms(terms)
    t = np.asarray(t_c, dtype=float)
    x = model_matrix(t, g_c_per_min, space, terms_t)
    n_in, p = x.shape
    t_in = t[in_region(t, g_c_per_min, space)]
    reached = (float(t_in.min()), float(t_in.max())) if t_in.size else (math.nan, math.nan)
    if t_in.size:  # a run that is in the region and beyond an edge has crossed that edge
        # (its last sample inside can be a degree short of it on a fast pass)
        t_fin = t[np.isfinite(t)]
        reached = (
            space.approx_lo_c if t_fin.min() < space.approx_lo_c else reached[0],
            space.approx_hi_c if t_fin.max() > space.approx_hi_c else reached[1],
        )
    gt, gg = space.grid("working")
    gu, gv = space.code(gt, gg)
    xg = monomials(gu, gv, terms_t)
    i_star = _i_optimum(space, terms_t)
    cond = float(np.linalg.cond(x)) if n_in >= p else math.inf
    if n_in < p or not cond < math.sqrt(SINGULAR_COND):
        inf_map = np.full(gt.size, math.inf)
        return DesignReport(
            space=space,
            terms=terms_t,
            n_samples=int(t.size),
            n_in_region=int(n_in),
            d_efficiency_pct=0.0,
            a_efficiency_pct=0.0,
            i_efficiency_pct=0.0,
            mean_variance=math.inf,
            max_variance=math.inf,
            i_optimal_variance=i_star,
            log_det=-math.inf,
            condition_number=cond,
            variance_map=pd.DataFrame(
                {"t_c": gt, "g_c_per_min": gg, "prediction_variance": inf_map}
            ),
            reached_lo_c=reached[0],
            reached_hi_c=reached[1],
        )
    m = x.T @ x / n_in
    m_inv = np.linalg.inv(m)
    var = np.einsum("ij,jk,ik->i", xg, m_inv, xg)
    w = xg.T @ xg / xg.shape[0]
    mean_var = -i_optimality(m, w)  # tr(W M^-1) = mean of var over the grid
    return DesignReport(
        space=space,
        terms=terms_t,
        n_samples=int(t.size),
        n_in_region=int(n_in),
        d_efficiency_pct=float(d_efficiency(x)),
        a_efficiency_pct=float(a_efficiency(x)),
        i_efficiency_pct=100.0 * i_star / mean_var,
        mean_variance=float(mean_var),
        max_variance=float(var.max()),
        i_optimal_variance=i_star,
        log_det=float(np.linalg.slogdet(m)[1]),
        condition_number=cond,
        variance_map=pd.DataFrame({"t_c": gt, "g_c_per_min": gg, "prediction_variance": var}),
        reached_lo_c=reached[0],
        reached_hi_c=reached[1],
    )


def programme_design(
    programme: Programme,
    space: DesignSpace,
    terms: str | tuple = "full",
    *,
    sample_min: float = SAMPLE_MIN,
) -> DesignReport:
    """:func:`design_report` of a programme simulated every ``sample_min`` with the
    space's device model, from the limits' initial temperature."""
    traj = simulate(programme, space.params, dt_min=sample_min, t0_c=space.limits.t_init_c)
    return design_report(traj.t_c, traj.g_c_per_min, space, terms)


def plan_space(plan) -> DesignSpace:
    """The :class:`DesignSpace` of a planner ``Plan`` (its regions, model, limits, caps)."""
    spec = plan.spec
    return DesignSpace(
        spec.working_lo_c,
        spec.working_hi_c,
        spec.approx_lo_c,
        spec.approx_hi_c,
        plan.params,
        plan.limits,
        spec.max_cool_c_per_min,
        spec.max_heat_c_per_min,
    )


def plan_design(plan, terms: str | tuple = "full") -> DesignReport:
    """:func:`design_report` of a planner ``Plan``'s exported programme (1-min samples)."""
    return programme_design(plan.programme, plan_space(plan), terms)


# -- the drift's level: a floor no programme and no fit can beat ---------------------------
#: Time step of the entry-time search, min.
ENTRY_STEP_MIN = 0.1


def first_entry_min(
    programme: Programme, space: DesignSpace, *, dt_min: float = ENTRY_STEP_MIN
) -> float:
    """When ``programme`` first brings the device into the approximation region, min
    (simulated with the space's device model from the limits' initial temperature; to
    ``dt_min``); ``inf`` if it never does."""
    traj = simulate(programme, space.params, dt_min=dt_min, t0_c=space.limits.t_init_c)
    inside = np.flatnonzero((traj.t_c >= space.approx_lo_c) & (traj.t_c <= space.approx_hi_c))
    return float(traj.time_min[inside[0]]) if inside.size else math.inf


def fastest_entry_min(space: DesignSpace, *, dt_min: float = ENTRY_STEP_MIN) -> float:
    """The earliest any programme within the space's limits can bring the device into the
    approximation region, min (``inf`` if none can within ``duration_max_min``).

    The device's temperature is monotone in the chamber's path (first-order lag), so the
    fastest entry from above is the chamber cooling at its full rate down to its floor and
    holding there; from below, heating at the full rate up to its ceiling.
    """
    lim = space.limits
    t0 = lim.t_init_c
    if space.approx_lo_c <= t0 <= space.approx_hi_c:
        return 0.0
    rate, stop = (
        (lim.rate_min_c_per_min, lim.chamber_min_c)
        if t0 > space.approx_hi_c
        else (lim.rate_max_c_per_min, lim.chamber_max_c)
    )
    total = lim.duration_max_min
    ramp = min((stop - lim.start_c) / rate, total) if rate else total
    if ramp <= 0.0:  # the chamber starts at (or beyond) its limit: hold there
        durations, rates = [total], [0.0]
    elif ramp < total:
        durations, rates = [ramp, total - ramp], [rate, 0.0]
    else:
        durations, rates = [total], [rate]
    programme = Programme(np.array(durations), np.array(rates), start_c=lim.start_c)
    return first_entry_min(programme, space, dt_min=dt_min)


def level_floor_dph(
    walk_dph_per_rt_h: float,
    white_dph_per_rt_hz: float,
    entry_min: float,
    record_min: float = math.inf,
) -> float:
    """The smallest RMS error, deg/h, with which any fit can know the drift's level when
    the device first reaches the approximation region ``entry_min`` after the bias random
    walk started (switch-on, the start of the run)::

        var >= K^2 t_entry + K N        (K in deg/h per sqrt(s), N in deg/h sqrt(s))

    The fit uses samples inside the approximation region only (outside it the drift
    polynomial is not assumed to hold), so the walk accumulated before the entry,
    variance ``K^2 t_entry``, is indistinguishable from the drift's constant; and even
    with the drift's shape known, a level observed through white noise N while it walks
    at K is known at the start of the record to ``sqrt(K N)`` at best (the stationary
    variance of the Kalman filter for a random walk in white noise, run backward from the
    end of an infinitely long record). A record of at most ``record_min`` from the entry
    on (what a run of that much more time can have) knows it worse, ``K N coth(K D / N)``
    (the same filter started at the record's end; ``N^2 / D`` without a walk). Every
    point of the compensation table carries the level, so this bounds the RMS error of
    the fitted drift over any grid (for any fit whose error does not depend on the
    drift's unknown level, as least squares' does not).
    """
    for name, v in (
        ("walk_dph_per_rt_h", walk_dph_per_rt_h),
        ("white_dph_per_rt_hz", white_dph_per_rt_hz),
        ("entry_min", entry_min),
        ("record_min", record_min),
    ):
        if not (v >= 0.0):
            raise ParameterError(f"{name} must be >= 0, got {v!r}")
    if record_min == 0.0:
        return math.inf  # nothing recorded in the region
    k = walk_dph_per_rt_h / 60.0  # deg/h per sqrt(s)
    n = white_dph_per_rt_hz
    record_s = record_min * 60.0
    if k == 0.0:
        at_entry = n * n / record_s  # white noise alone: its mean over the record
    elif n == 0.0:
        at_entry = 0.0  # the level at the entry is read off exactly
    else:
        at_entry = k * n / math.tanh(k * record_s / n)
    return math.sqrt(k * k * entry_min * 60.0 + at_entry)


#: The shape part of :func:`fit_error_floor_dph` takes its optimum's certificate over the
#: reachable band on a grid this much finer than the candidates' (and on the band's edges).
CERTIFICATE_REFINE = 10


def every_gradient(space: DesignSpace) -> DesignSpace:
    """``space`` with the chamber's rate limits as its fastest gradients: its band then
    holds every run that keeps within the device limits (a gradient relaxes towards the
    chamber's rate, so it never passes it), not only the planner's."""
    lim = space.limits
    return replace(
        space,
        max_cool_c_per_min=max(-lim.rate_min_c_per_min, 1e-9),
        max_heat_c_per_min=max(lim.rate_max_c_per_min, 1e-9),
    )


@lru_cache(maxsize=64)
def shape_floor_factor(
    space: DesignSpace, terms: tuple[str, ...], reach: DesignSpace | None = None
) -> float:
    """``L*``: the smallest mean variance of the fitted drift's *shape* over the working
    grid that any distribution of samples on the reachable band of the approximation
    region gives, in units of ``N^2 / D`` (white noise N, D seconds of samples; module
    docstring of :func:`fit_error_floor_dph`).

    ``L* = min_xi tr(M(xi)^-1 C)``, ``C`` the covariance of the terms over the working
    grid (the grid's mean, the level, taken out); an L-optimal design, convex in the
    weights, found by :func:`i_optimal_design` on the candidate grid of the band the
    samples can lie on (``reach``'s approximation region and band, by default
    :func:`every_gradient` of ``space``) and its edges. What is returned is its **lower
    bound** by convexity, ``2 L(w) - max d(x)`` with ``d`` the directional derivative over
    a grid :data:`CERTIFICATE_REFINE` times finer (edges included): a finer or continuous
    design cannot beat it (to that grid's resolution). ``terms``: a tuple of term names
    (:func:`~schedsyn.terms.parse_terms`; hashable, the result is cached).
    """
    terms_t = parse_terms(terms)
    t_w, g_w = space.grid("working")
    z = monomials(*space.code(t_w, g_w), terms_t)
    zc = z - z.mean(axis=0)
    cov = zc.T @ zc / z.shape[0]

    reach = every_gradient(space) if reach is None else reach

    def band(t_step_c: float, g_step: float) -> np.ndarray:
        # the grid over the band and its edges (where the optimum puts much of its weight),
        # in the working grid's coding
        t, g = reach.grid("approx", t_step_c, g_step)
        n_t = max(int(round((reach.approx_hi_c - reach.approx_lo_c) / t_step_c)), 1)
        t_e = np.linspace(reach.approx_lo_c, reach.approx_hi_c, n_t + 1)
        g_lo, g_hi = reach.gradient_band(t_e)
        return monomials(
            *space.code(np.concatenate([t, t_e, t_e]), np.concatenate([g, g_lo, g_hi])),
            terms_t,
        )

    c = band(CANDIDATE_T_STEP_C, CANDIDATE_G_STEP_C_PER_MIN)
    phi, w = i_optimal_design(c, cov)
    m_inv = np.linalg.inv(c.T @ (w[:, None] * c))
    f = band(
        CANDIDATE_T_STEP_C / CERTIFICATE_REFINE, CANDIDATE_G_STEP_C_PER_MIN / CERTIFICATE_REFINE
    )
    d_max = float(np.einsum("ij,jk,ik->i", f, m_inv @ cov @ m_inv, f).max())
    return max(2.0 * phi - d_max, 0.0)


def fit_error_floor_dph(
    space: DesignSpace,
    walk_dph_per_rt_h: float,
    white_dph_per_rt_hz: float,
    entry_min: float,
    duration_min: float,
    terms: str | tuple = "full",
    reach: DesignSpace | None = None,
) -> float:
    """The smallest RMS error over the working grid, deg/h, with which any run of
    ``duration_min`` (switch-on at 0, first in the approximation region at ``entry_min``)
    can fit the drift polynomial ``terms`` by a linear unbiased fit (least squares,
    weighted or not, with T and g known: estimating them only adds)::

        MSE >= K^2 t_e + K N coth(K D / N) + (N^2 / D) L*        D = duration - t_e

    ``space`` gives the working grid the error is taken over; ``reach`` the band the
    samples can lie on, by default :func:`every_gradient` of ``space`` (give the device's
    ``params``: the band then holds every run within the device limits,
    :func:`reachable_gradients`).

    Why: with ``f = (1, f_s)`` the terms, ``W`` their mean square over the grid and ``v``
    their mean, ``tr(M^-1 W) = v' M^-1 v + tr((M^-1)_ss C)``, ``C = W - v v'`` (only the
    shape block). By Cauchy-Schwarz ``v' M^-1 v >= 1 / M_00``, the variance of the
    level with the shape known: the walk before the entry plus the level at the entry
    seen through white noise from a record of at most ``D`` (the backward Kalman filter of
    a random walk, ``K N coth(K D / N)``; :func:`level_floor_dph` is its long-record
    limit). ``(M^-1)_ss`` is the shape's covariance with the level a nuisance; told the
    walk (an oracle), a fit only gains, and what is left is white noise of ``N^2 / h``
    per sample over at most ``D`` seconds: ``(N^2 / D) Cov_xi(f_s)^-1`` for the samples'
    distribution ``xi``, whose best over the band is :func:`shape_floor_factor`.
    """
    for name, v in (
        ("walk_dph_per_rt_h", walk_dph_per_rt_h),
        ("white_dph_per_rt_hz", white_dph_per_rt_hz),
        ("entry_min", entry_min),
        ("duration_min", duration_min),
    ):
        if not (v >= 0.0):
            raise ParameterError(f"{name} must be >= 0, got {v!r}")
    record_min = duration_min - entry_min
    if not record_min > 0.0:
        return math.inf  # the run never reaches the region
    level = level_floor_dph(walk_dph_per_rt_h, white_dph_per_rt_hz, entry_min, record_min)
    shape = (
        white_dph_per_rt_hz**2
        / (record_min * 60.0)
        * shape_floor_factor(space, parse_terms(terms), reach)
    )
    return math.sqrt(level**2 + shape)


@dataclass(frozen=True)
class FitErrorPrediction:
    """The drift fit's expected error for one run and one gyro's noise, deg/h
    (:func:`predicted_fit_error`)."""

    #: RMS over the working region's T x g grid of the fitted drift's standard error
    total_dph: float
    #: the same with the drift's level (the grid mean) removed: the error of its shape
    shape_dph: float
    #: samples of the run inside the approximation region that the prediction uses
    n_samples: int
    white_noise_dph_per_rt_hz: float
    bias_walk_dph_per_rt_h: float
    terms: str

    def summary(self) -> str:
        return (
            f"predicted drift-fit error ({self.terms} model, white noise "
            f"{self.white_noise_dph_per_rt_hz:g} °/h/√Hz, bias walk "
            f"{self.bias_walk_dph_per_rt_h:g} °/h/√h; RMS over the working region's T x g "
            f"grid): {self.total_dph:.4g} °/h, {self.shape_dph:.4g} °/h with the level "
            "removed"
        )


def predicted_fit_error(
    time_min: np.ndarray,
    t_c: np.ndarray,
    g_c_per_min: np.ndarray,
    space: DesignSpace,
    white_noise_dph_per_rt_hz: float,
    bias_walk_dph_per_rt_h: float,
    terms: str | tuple = "full",
) -> FitErrorPrediction:
    """How well a run determines the drift polynomial, given the gyro's noise, before it is
    run: the standard error of the generalised-least-squares fit of ``terms`` to the
    samples inside the approximation region, RMS over the working region's grid
    (``space.grid("working")``), total and with the level removed.

    The drift readings are modelled as the polynomial plus a bias random walk of ``K`` =
    ``bias_walk_dph_per_rt_h`` started at ``time_min = 0`` (switch-on) and white noise of
    density ``N`` = ``white_noise_dph_per_rt_hz`` averaged over each sample's period ``h``
    (the spacing of ``time_min``; :mod:`schedsyn.gyro`'s readings), so their covariance is
    ``Omega = K^2 min(t_i, t_j) + (N^2 / h) I`` and the coefficients' covariance is
    ``(X' Omega^-1 X)^-1``. The temperature and gradient are taken as known (the planned
    trajectory); the fit's own gradient estimate adds to this. Unlike the D-, A- and
    I-criteria (which are per sample and blind to the walk), this counts the walk that
    the region's samples share: it is what no choice of the samples' gradients removes
    (:func:`level_floor_dph` is its bound on the level).
    """
    for name, v in (
        ("white_noise_dph_per_rt_hz", white_noise_dph_per_rt_hz),
        ("bias_walk_dph_per_rt_h", bias_walk_dph_per_rt_h),
    ):
        if not (math.isfinite(v) and v >= 0.0):
            raise ParameterError(f"{name} must be a number >= 0, got {v!r}")
    if white_noise_dph_per_rt_hz == 0.0 and bias_walk_dph_per_rt_h == 0.0:
        raise ParameterError(
            "a noise-free gyro is fitted exactly: give white_noise_dph_per_rt_hz or "
            "bias_walk_dph_per_rt_h > 0"
        )
    time = np.asarray(time_min, dtype=float)
    t = np.asarray(t_c, dtype=float)
    g = np.asarray(g_c_per_min, dtype=float)
    if not (time.shape == t.shape == g.shape) or time.ndim != 1 or time.size < 2:
        raise ParameterError("time_min, t_c and g_c_per_min must be 1-D and of one length >= 2")
    if not (np.isfinite(time).all() and (np.diff(time) > 0).all() and time[0] >= 0.0):
        raise ParameterError("time_min must be finite, >= 0 and increasing (min since switch-on)")
    period_s = np.diff(time, prepend=time[0] - (time[1] - time[0])) * 60.0
    terms_t = parse_terms(terms)
    inside = in_region(t, g, space)
    x = monomials(*space.code(t[inside], g[inside]), terms_t)
    if x.shape[0] < x.shape[1]:
        raise ParameterError(
            f"{int(inside.sum())} samples in the approximation region [{space.approx_lo_c:g}, "
            f"{space.approx_hi_c:g}] °C, fewer than the {x.shape[1]} terms to fit"
        )
    hours = time[inside] / 60.0
    omega = bias_walk_dph_per_rt_h**2 * np.minimum.outer(hours, hours)
    omega[np.diag_indices_from(omega)] += white_noise_dph_per_rt_hz**2 / period_s[inside]
    try:
        chol = np.linalg.cholesky(omega)
    except np.linalg.LinAlgError:  # no white noise and a sample at switch-on
        raise ParameterError(
            "the readings' covariance is singular: give white_noise_dph_per_rt_hz > 0"
        ) from None
    w = np.linalg.solve(chol, x)  # Omega^-1/2 X
    info = w.T @ w
    if not np.linalg.cond(info) < SINGULAR_COND:
        raise ParameterError(
            "the run's samples do not determine every term (singular information): fit "
            "fewer terms, or plan a run with more distinct gradients in the region"
        )
    cov = np.linalg.inv(info)
    z = monomials(*space.code(*space.grid("working")), terms_t)
    zc = z - z.mean(axis=0)
    return FitErrorPrediction(
        total_dph=math.sqrt(float(np.einsum("ij,jk,ik->i", z, cov, z).mean())),
        shape_dph=math.sqrt(max(float(np.einsum("ij,jk,ik->i", zc, cov, zc).mean()), 0.0)),
        n_samples=int(inside.sum()),
        white_noise_dph_per_rt_hz=float(white_noise_dph_per_rt_hz),
        bias_walk_dph_per_rt_h=float(bias_walk_dph_per_rt_h),
        terms=term_set_name(terms_t),
    )
