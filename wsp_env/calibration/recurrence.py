"""The calibration's one compiled loop: the first-order lag's pass over a log's samples
(``residuals.first_order``). A recurrence over thousands of samples is a Python loop's worst
case (one interpreted step a sample: 15-20 ms a call on a 60 s log, 1,060 calls in two of the
calibration test modules); compiled, the same arithmetic in the same order (no fast-math) gives the
same numbers bit for bit (``tests/test_calibration_forms.py``)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def lag_pass(u: np.ndarray, a: np.ndarray, slope: np.ndarray, tcs: np.ndarray) -> np.ndarray:
    """``y[k] = u[k] - ts + (y[k-1] - u[k-1] + ts) a[k-1]`` with ``ts = tcs slope[k-1]``, per
    column, from ``y[0] = u[0]``: ``u`` (samples, columns), ``a`` and ``slope`` (samples - 1,
    columns), ``tcs`` (columns,)."""
    n, m = u.shape
    y = np.empty((n, m))
    for c in range(m):
        y[0, c] = u[0, c]
    for k in range(1, n):
        for c in range(m):
            ts = tcs[c] * slope[k - 1, c]
            y[k, c] = u[k, c] - ts + (y[k - 1, c] - u[k - 1, c] + ts) * a[k - 1, c]
    return y
