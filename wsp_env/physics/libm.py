"""The C library's elementary functions applied element by element to an array.

numpy's ufuncs ``exp``, ``log``, ``power``, ``arccos``, ``cbrt``, ``tanh``, ``arctan``, ``expm1``
and ``log1p`` use numpy's own vector routines where the CPU has them (numpy 2.4: its ``X86_V4``,
AVX-512, dispatch), and those differ from the C library's in the last bit (on one AVX-512 host:
5 % of arguments for exp and power, half for cbrt); on an AVX2 CPU numpy calls the C library for
all of them but tanh. A last bit that differs in one axle's creep stiffness moves a stop by up to
metres where a valve's threshold is crossed one period earlier or later. The compiled kernels
call the C library's functions (numba); what the set-up computes before them goes through
:func:`elementwise`, so a run's result depends on its seed and the C library, not on numpy's
choice of code for the CPU (``tests/test_cpu_independence.py``; docs/physics.md, "Results across
CPUs"). Sums and products are IEEE operations, the same on every CPU.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["elementwise"]


def elementwise(fn: Callable[[float], float], x: ArrayLike) -> NDArray[np.float64]:
    """``fn`` (a function of ``math``, or one built of them: the C library's) applied to each
    element of ``x``; a float64 array of ``x``'s shape (a numpy float64 for a scalar, as a ufunc
    gives). For the set-up's small arrays (a value an axle), not for a kernel's inner loop."""
    arr = np.asarray(x, dtype=np.float64)
    out = np.array([fn(v) for v in arr.ravel().tolist()], dtype=np.float64).reshape(arr.shape)
    return out[()] if out.ndim == 0 else out
