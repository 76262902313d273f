"""The one definition of the temperature bins shared by the planner and the coverage metric."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError


@dataclass(frozen=True, slots=True)
class BinGrid:
    """Working region ``[lo_c, hi_c]`` split into bins ``[lo + k w, lo + (k+1) w)``.

    Parameters
    ----------
    lo_c, hi_c : float
        Working region, degC, ``lo_c < hi_c``.
    bin_c : float
        Bin width, degC (default 1). ``hi_c - lo_c`` must be a whole number of bins.
    """

    lo_c: float
    hi_c: float
    bin_c: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lo_c", "hi_c", "bin_c"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")
        if not self.lo_c < self.hi_c:
            raise ParameterError(
                f"the working region must have lo_c < hi_c, got {self.lo_c} .. {self.hi_c} "
                "degC; give its lower edge first"
            )
        if self.bin_c <= 0:
            raise ParameterError(f"bin_c must be > 0 degC, got {self.bin_c}")
        n = (self.hi_c - self.lo_c) / self.bin_c
        if abs(n - round(n)) > 1e-9:
            raise ParameterError(
                f"the working region {self.lo_c} .. {self.hi_c} degC is not a whole number of "
                f"{self.bin_c} degC bins"
            )

    @property
    def n_bins(self) -> int:
        return int(round((self.hi_c - self.lo_c) / self.bin_c))

    @property
    def edges_c(self) -> np.ndarray:
        return self.lo_c + self.bin_c * np.arange(self.n_bins + 1)

    @property
    def lower_c(self) -> np.ndarray:
        return self.edges_c[:-1]

    @property
    def centres_c(self) -> np.ndarray:
        return self.lower_c + 0.5 * self.bin_c

    def index(self, temps_c: np.ndarray) -> np.ndarray:
        """Bin index of each temperature, -1 outside ``[lo_c, hi_c)``."""
        t = np.asarray(temps_c, dtype=float)
        finite = np.isfinite(t)
        k = np.floor((np.where(finite, t, self.lo_c - self.bin_c) - self.lo_c) / self.bin_c)
        k = k.astype(np.int64)
        # guard against floor's rounding at the exact upper edge
        k = np.where(self.lo_c + k * self.bin_c > t, k - 1, k)
        inside = (k >= 0) & (k < self.n_bins) & finite
        return np.where(inside, k, -1)
