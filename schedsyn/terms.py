"""The drift polynomial's terms: one definition for the synthetic gyro, the fit and the design.

The drift of a gyro is modelled as a polynomial of total order <= 3 in the internal
temperature ``T`` (degC, about a reference ``t_ref_c``) and its gradient ``g = dT/dt``
(degC/min)::

    drift_dph = sum_k c_k (T - t_ref)^a_k g^b_k,     a_k + b_k <= 3

with ten terms named after their powers::

    1, t, g, t2, tg, g2, t3, t2g, tg2, g3

A coefficient ``c_k`` is in deg/h per degC^a_k per (degC/min)^b_k (:func:`unit_of`).

Fitting and design work in *coded* variables ``x = (T - t_ref)/t_half`` and ``y = (g -
g_mid)/g_half``. A coded coefficient is converted to physical units by expanding the
coded polynomial (:func:`coded_to_physical`); with ``g_mid = 0`` (what the fit uses) the
map is diagonal, ``c_k = c_k' / (t_half^a_k g_half^b_k)``, so any subset of terms stays
closed under it.

Errors in the regressors: if ``(x_hat, y_hat) = (x, y) + e`` with ``e ~ N(0, S)``, then
``E[m*(x_hat, y_hat)] = x^a y^b`` for the corrected monomial (:func:`corrected_monomials`)::

    m* = exp(-D) x^a y^b,   D = 1/2 (Sxx d2/dx2 + 2 Sxy d2/dxdy + Syy d2/dy2)

(the inverse of the Gaussian smoothing ``E[p(z + e)] = exp(D) p(z)``; a finite sum for a
polynomial), e.g. ``x^2 -> x^2 - Sxx``, ``x^3 -> x^3 - 3 Sxx x``, ``xy -> xy - Sxy``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from .errors import ParameterError

#: The ten terms of the full model, in canonical order.
TERMS: tuple[str, ...] = ("1", "t", "g", "t2", "tg", "g2", "t3", "t2g", "tg2", "g3")
#: Powers ``(a, b)`` of ``(T - t_ref, g)`` of each term.
EXPONENTS: dict[str, tuple[int, int]] = {
    "1": (0, 0),
    "t": (1, 0),
    "g": (0, 1),
    "t2": (2, 0),
    "tg": (1, 1),
    "g2": (0, 2),
    "t3": (3, 0),
    "t2g": (2, 1),
    "tg2": (1, 2),
    "g3": (0, 3),
}
#: Named term sets, nested by their order in g (each has every term of total order <= 3
#: up to that order in g). ``t-only`` is the reference model (a cubic in T, as PX4's and
#: ArduPilot's thermal calibrations fit).
TERM_SETS: dict[str, tuple[str, ...]] = {
    "t-only": ("1", "t", "t2", "t3"),
    "g1": ("1", "t", "g", "t2", "tg", "t3", "t2g"),
    "g2": ("1", "t", "g", "t2", "tg", "g2", "t3", "t2g", "tg2"),
    "full": TERMS,
}
#: The candidates term selection compares, simplest first.
CANDIDATES: tuple[str, ...] = ("t-only", "g1", "g2", "full")


def parse_terms(spec: str | Sequence[str]) -> tuple[str, ...]:
    """Terms from a set name (``t-only``, ``g1``, ``g2``, ``full``) or a list of term names.

    A string with commas is a list (``"1,t,t2,t3,g"``). The result is in canonical order
    and always contains the constant ``1`` (the bias random walk's start level and the
    mean drift need it).

    Raises
    ------
    ParameterError
        Unknown set or term name, a repeated term, or no constant term.
    """
    if isinstance(spec, str):
        s = spec.strip()
        if s in TERM_SETS:
            return TERM_SETS[s]
        names = [n.strip() for n in s.split(",") if n.strip()]
        if len(names) <= 1 and (not names or names[0] not in EXPONENTS):
            raise ParameterError(
                f"unknown term set {spec!r}; use one of {', '.join(TERM_SETS)} or a comma "
                f"list of terms from {', '.join(TERMS)}"
            )
    else:
        names = [str(n).strip() for n in spec]
    unknown = [n for n in names if n not in EXPONENTS]
    if unknown:
        raise ParameterError(
            f"unknown drift term(s) {', '.join(unknown)}; the terms are {', '.join(TERMS)} "
            "(t: T - t_ref in °C, g: gradient in °C/min)"
        )
    if len(set(names)) != len(names):
        raise ParameterError(f"a drift term is repeated in {', '.join(names)}")
    if "1" not in names:
        raise ParameterError(
            f"the terms {', '.join(names)} lack the constant term 1; add it (the mean drift "
            "and the bias random walk's level need it)"
        )
    return tuple(t for t in TERMS if t in names)


def term_set_name(terms: Sequence[str]) -> str:
    """The set name of ``terms`` if it is a named set, else the comma list."""
    terms = tuple(terms)
    for name, ts in TERM_SETS.items():
        if ts == terms:
            return name
    return ",".join(terms)


def unit_of(term: str) -> str:
    """Unit of a term's physical coefficient, e.g. ``°/h/(°C^2·°C/min)`` for ``t2g``."""
    a, b = EXPONENTS[term]
    parts = []
    if a:
        parts.append("°C" if a == 1 else f"°C^{a}")
    if b:
        parts.append("°C/min" if b == 1 else f"(°C/min)^{b}")
    if not parts:
        return "°/h"
    if len(parts) == 1 and a:
        return f"°/h/{parts[0]}"
    return f"°/h/({'·'.join(parts)})"


def monomials(x: np.ndarray, y: np.ndarray, terms: Sequence[str]) -> np.ndarray:
    """Model matrix ``X[k, i] = x_k^a_i y_k^b_i`` (n x p) of the terms."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return np.column_stack([x ** EXPONENTS[t][0] * y ** EXPONENTS[t][1] for t in terms])


def evaluate(
    coefficients: Sequence[float] | np.ndarray,
    terms: Sequence[str],
    x: np.ndarray,
    y: np.ndarray,
) -> np.ndarray:
    """``sum_i c_i x^a_i y^b_i`` at every ``(x, y)``."""
    return monomials(x, y, terms) @ np.asarray(coefficients, dtype=float)


def corrected_monomials(
    x: np.ndarray,
    y: np.ndarray,
    sxx: np.ndarray | float,
    sxy: np.ndarray | float,
    syy: np.ndarray | float,
    powers: Iterable[tuple[int, int]],
) -> dict[tuple[int, int], np.ndarray]:
    """Unbiased estimates of ``x^a y^b`` from error-laden ``(x, y)`` (module docstring).

    ``m* = sum_{i,j,l} (-Sxx/2)^i/i! (-Syy/2)^j/j! (-Sxy)^l/l!
    a!/(a-2i-l)! b!/(b-2j-l)! x^(a-2i-l) y^(b-2j-l)``, the expansion of ``exp(-D)``.
    ``sxx, sxy, syy`` may be per-sample arrays (heteroscedastic errors). With all of them
    zero, ``m* = x^a y^b``.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    sxx_a = np.broadcast_to(np.asarray(sxx, dtype=float), x.shape)
    sxy_a = np.broadcast_to(np.asarray(sxy, dtype=float), x.shape)
    syy_a = np.broadcast_to(np.asarray(syy, dtype=float), x.shape)
    out: dict[tuple[int, int], np.ndarray] = {}
    fact = math.factorial
    for a, b in powers:
        total = np.zeros_like(x)
        for i in range(a // 2 + 1):
            for l_ in range(min(a - 2 * i, b) + 1):
                for j in range((b - l_) // 2 + 1):
                    pa, pb = a - 2 * i - l_, b - 2 * j - l_
                    c = (
                        fact(a)
                        / fact(pa)
                        * fact(b)
                        / fact(pb)
                        / (fact(i) * fact(j) * fact(l_))
                        * (-0.5) ** i
                        * (-0.5) ** j
                        * (-1.0) ** l_
                    )
                    total = total + c * sxx_a**i * syy_a**j * sxy_a**l_ * x**pa * y**pb
        out[(a, b)] = total
    return out


def coded_to_physical(
    terms: Sequence[str],
    t_ref_c: float,
    t_half_c: float,
    g_mid_c_per_min: float,
    g_half_c_per_min: float,
    t_ref_out_c: float | None = None,
) -> np.ndarray:
    """Matrix ``J`` with ``c_phys = J @ c_coded`` for the terms of the full model.

    The coded polynomial uses ``x = (T - t_ref)/t_half`` and ``y = (g - g_mid)/g_half``;
    the physical one ``(T - t_ref_out)`` and ``g``. Rows and columns follow ``TERMS``
    restricted to ``terms`` for the columns, all ten ``TERMS`` for the rows (an affine
    shift can create lower terms that are not in ``terms``).
    """
    if not (t_half_c > 0 and g_half_c_per_min > 0):
        raise ParameterError("coding half-widths must be > 0")
    t_out = t_ref_c if t_ref_out_c is None else t_ref_out_c
    # x = (T' + s)/t_half with T' = T - t_out, s = t_out - t_ref ; y = (g - g_mid)/g_half
    s = t_out - t_ref_c
    rows = {t: i for i, t in enumerate(TERMS)}
    j_mat = np.zeros((len(TERMS), len(terms)))
    for col, term in enumerate(terms):
        a, b = EXPONENTS[term]
        scale = 1.0 / (t_half_c**a * g_half_c_per_min**b)
        for p in range(a + 1):  # (T' + s)^a = sum_p C(a,p) T'^p s^(a-p)
            for q in range(b + 1):  # (g - g_mid)^b = sum_q C(b,q) g^q (-g_mid)^(b-q)
                c = math.comb(a, p) * s ** (a - p) * math.comb(b, q) * (-g_mid_c_per_min) ** (b - q)
                j_mat[rows[_name(p, q)], col] += scale * c
    return j_mat


def _name(a: int, b: int) -> str:
    for t, e in EXPONENTS.items():
        if e == (a, b):
            return t
    raise KeyError((a, b))
