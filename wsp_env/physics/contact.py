"""Wheel–rail contact stiffness for the Polach creep-force law.

Hertz contact ellipse + Kalker's linear-theory coefficient c11 give the longitudinal creep
stiffness ``G a b c11`` (N per unit creepage, one wheel) that fixes the initial slope of the
Polach (2005) creep-force curve. This follows seed 001 ("Approach 2": Hertz normal problem,
then Kalker / Polach tangential problem).

Pure numpy, vectorised over arrays of loads (all arguments broadcast against each other);
meant to be called once when a vehicle configuration is loaded, not in the simulation loop.
Scalar inputs give 0-d arrays (``float(x)`` works on them).

Load scaling: in Hertz theory ``a`` and ``b`` are proportional to ``Q**(1/3)`` and their ratio
does not depend on the load, so c11 does not either, and the stiffness ``G a b c11`` is
proportional to ``Q**STIFFNESS_LOAD_EXPONENT`` with ``STIFFNESS_LOAD_EXPONENT == 2/3``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wsp_env.physics.libm import elementwise

__all__ = [
    "STIFFNESS_LOAD_EXPONENT",
    "hertz_coefficients",
    "hertz_semi_axes",
    "kalker_c11",
    "kalker_longitudinal_stiffness_N",
]

FloatArray = NDArray[np.float64]

STIFFNESS_LOAD_EXPONENT: float = 2.0 / 3.0
"""Exponent p in ``G a b c11 ∝ Q**p`` (Hertz: a, b ∝ Q^(1/3); c11 depends only on a/b)."""

# --------------------------------------------------------------------------------------------
# Hertz m, n coefficients as a function of theta (degrees), cos(theta) = |B - A| / (A + B).
# Source: seed 001 (Approach 2, Hertz m/n table), which is the classical Hertz table
# (e.g. Timoshenko & Goodier). The seed prints n = 0.439 at 30 deg; that is a transposition
# typo: the classical table gives 0.493, and 0.439 would make n non-monotonic between 0.567
# (40 deg) and 0.408 (20 deg). The exact elliptic-integral solution gives 0.4930 at 30 deg
# (checked in tests/test_contact.py), so 0.493 is used.
# --------------------------------------------------------------------------------------------
_HERTZ_THETA_DEG = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0])
_HERTZ_M = np.array([6.612, 3.778, 2.731, 2.136, 1.754, 1.486, 1.284, 1.128, 1.000])
_HERTZ_N = np.array([0.319, 0.408, 0.493, 0.567, 0.641, 0.717, 0.802, 0.893, 1.000])
_LOG_HERTZ_M = elementwise(math.log, _HERTZ_M)
_LOG_HERTZ_N = elementwise(math.log, _HERTZ_N)

# --------------------------------------------------------------------------------------------
# Kalker (1967) creepage coefficient c11, columns nu = 0, 0.25, 0.5, rows g = 0.1 ... 1.0.
# Verified against Table E.3 of Kalker, "Three-dimensional elastic bodies in rolling contact"
# (1990), as embedded in the open-source CONTACT code by E.A.H. Vollebregt & J.J. Kalker
# (github.com/eve70a/CONTACT, src/m_hertz.f90, subroutine ``linrol``): identical numbers.
# --------------------------------------------------------------------------------------------
_KALKER_NU = np.array([0.0, 0.25, 0.5])
_KALKER_G = np.round(np.arange(1, 11) / 10.0, 1)
# a/b = g <= 1 (contact ellipse shorter in the rolling direction)
_C11_A_LE_B = np.array(
    [
        [2.51, 3.31, 4.85],
        [2.59, 3.37, 4.81],
        [2.68, 3.44, 4.80],
        [2.78, 3.53, 4.82],
        [2.88, 3.62, 4.83],
        [2.98, 3.72, 4.91],
        [3.09, 3.81, 4.97],
        [3.19, 3.91, 5.05],
        [3.29, 4.01, 5.12],
        [3.40, 4.12, 5.20],
    ]
)
# b/a = g <= 1 (contact ellipse longer in the rolling direction)
_C11_A_GE_B = np.array(
    [
        [10.7, 11.7, 12.9],
        [6.96, 7.78, 8.82],
        [5.57, 6.34, 7.34],
        [4.84, 5.57, 6.57],
        [4.37, 5.10, 6.11],
        [4.06, 4.78, 5.80],
        [3.82, 4.54, 5.58],
        [3.65, 4.36, 5.42],
        [3.51, 4.22, 5.30],
        [3.40, 4.12, 5.20],
    ]
)
# Exact limit a/b -> 0 (Kalker): c11 = pi^2 / (4 (1 - nu)); prepended as a g = 0 row so that
# a/b < 0.1 interpolates between the asymptote and the first table row.
_C11_A_LE_B_WITH_LIMIT = np.vstack([np.pi**2 / (4.0 * (1.0 - _KALKER_NU)), _C11_A_LE_B])
_KALKER_G_WITH_ZERO = np.concatenate([[0.0], _KALKER_G])


def _as_float_array(name: str, value: ArrayLike) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64)
    if np.isnan(arr).any():
        raise ValueError(f"{name} contains NaN")
    return arr


def _check_positive(name: str, value: ArrayLike, *, allow_inf: bool = False) -> FloatArray:
    arr = _as_float_array(name, value)
    if not np.all(arr > 0.0):
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if not allow_inf and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return arr


def _check_poisson_open(name: str, value: ArrayLike) -> FloatArray:
    arr = _as_float_array(name, value)
    if not np.all((arr > 0.0) & (arr < 0.5)):
        raise ValueError(f"{name} (Poisson's ratio) must lie in the open interval (0, 0.5)")
    return arr


def hertz_coefficients(theta_deg: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Hertz coefficients ``(m, n)`` for ``theta`` in degrees, 10 <= theta <= 90.

    Table from seed 001 (Approach 2, Hertz m/n table) with the 30-degree n corrected to 0.493.
    Interpolated linearly in ``log m`` / ``log n`` versus theta (m grows roughly
    exponentially as theta -> 0). ``m >= 1 >= n``; m = n = 1 at 90 degrees (circle).
    """
    theta = _as_float_array("theta_deg", theta_deg)
    if not np.all((theta >= _HERTZ_THETA_DEG[0]) & (theta <= _HERTZ_THETA_DEG[-1])):
        raise ValueError(
            "theta must lie in [10, 90] degrees (range of the Hertz m/n table); "
            f"got {theta_deg!r}. The contact ellipse is too elongated for this table."
        )
    m = elementwise(math.exp, np.interp(theta, _HERTZ_THETA_DEG, _LOG_HERTZ_M))
    n = elementwise(math.exp, np.interp(theta, _HERTZ_THETA_DEG, _LOG_HERTZ_N))
    return m, n


def hertz_semi_axes(
    wheel_load_N: ArrayLike,
    wheel_radius_m: ArrayLike,
    rail_crown_radius_m: ArrayLike = 0.3,
    wheel_transverse_radius_m: ArrayLike = math.inf,
    youngs_modulus_Pa: ArrayLike = 2.1e11,
    poisson: ArrayLike = 0.3,
) -> tuple[FloatArray, FloatArray]:
    """Hertz contact-ellipse semi-axes ``(a, b)`` in metres; ``a`` rolling, ``b`` lateral.

    Seed 001 (Approach 2, Hertz m/n table). Curvature sums (straight rail, R2x = inf)::

        A = 0.5 / wheel_radius
        B = 0.5 * (1 / wheel_transverse_radius + 1 / rail_crown_radius)
        cos(theta) = |B - A| / (A + B)
        c = [3 Q (1 - nu^2) / (2 E (A + B))]^(1/3)
        major semi-axis = m(theta) c,   minor semi-axis = n(theta) c

    The major axis lies along the direction of smaller curvature: rolling (``a``) if A < B,
    lateral (``b``) if A > B.

    Factor 2: with both bodies steel, Hertz's contact modulus is
    ``1/E* = 2 (1 - nu^2) / E``, and with the half-curvature convention above
    (A + B = half the sum of the four principal curvatures), Hertz gives
    ``c^3 = 3 Q / (4 E* (A + B)) = 3 Q (1 - nu^2) / (2 E (A + B))``. In the circular limit
    (A = B) this reduces to the textbook ``a^3 = 3 Q R / (4 E*)``, ``R = 1 / (2 A)``.
    The seed writes ``3 N (1 - nu^2) / (E (A + B))`` without the 2; that form only holds if
    A + B is the *full* curvature sum (no factor 0.5). With the 0.5 convention it would
    overestimate the axes by 2^(1/3) = 1.26, so the seed's form is not used here.

    Radii must be > 0; ``wheel_transverse_radius_m`` and ``rail_crown_radius_m`` may be
    ``inf`` (flat profile), but not both. Concave (negative) profile radii are not supported.
    """
    Q = _check_positive("wheel_load_N", wheel_load_N)
    R1x = _check_positive("wheel_radius_m", wheel_radius_m)
    R2y = _check_positive("rail_crown_radius_m", rail_crown_radius_m, allow_inf=True)
    R1y = _check_positive("wheel_transverse_radius_m", wheel_transverse_radius_m, allow_inf=True)
    E = _check_positive("youngs_modulus_Pa", youngs_modulus_Pa)
    nu = _check_poisson_open("poisson", poisson)

    A = 0.5 / R1x
    B = 0.5 * (1.0 / R1y + 1.0 / R2y)
    if not np.all(B > 0.0):
        raise ValueError(
            "wheel_transverse_radius_m and rail_crown_radius_m cannot both be infinite "
            "(line contact: no Hertz ellipse)"
        )
    cos_theta = np.clip(np.abs(B - A) / (A + B), 0.0, 1.0)
    theta_deg = np.degrees(elementwise(math.acos, cos_theta))
    m, n = hertz_coefficients(theta_deg)
    c = elementwise(math.cbrt, 3.0 * Q * (1.0 - nu**2) / (2.0 * E * (A + B)))
    rolling_is_major = A <= B
    a = np.where(rolling_is_major, m, n) * c
    b = np.where(rolling_is_major, n, m) * c
    return a, b


def kalker_c11(a_over_b: ArrayLike, poisson: ArrayLike) -> FloatArray:
    """Kalker's longitudinal creepage coefficient c11(a/b, nu) (Kalker 1967 / Polach 2005).

    Table values (nu = 0, 0.25, 0.5; g = min(a/b, b/a) = 0.1 ... 1.0) verified against
    Kalker's Table E.3 as embedded in the open-source CONTACT code (Vollebregt & Kalker,
    github.com/eve70a/CONTACT, ``src/m_hertz.f90``, ``linrol``).

    Interpolation: linear in g within each nu column, then in nu by the parabola through the
    three columns fitted to 1/c11 (the scheme used by CONTACT). Fitting 1/c11 rather than c11
    reproduces the exact small-g asymptote c11 = pi^2 / (4 (1 - nu)), for which 1/c11 is
    linear in nu; plain linear interpolation of c11 in nu overestimates c11 by ~2.5 % at
    nu = 0.3, a/b = 0.1. Both reproduce the table exactly at the grid points.

    Range: a/b in (0, 10], nu in [0, 0.5]. For a/b < 0.1 the value is interpolated linearly
    between the table row g = 0.1 and the exact limit pi^2 / (4 (1 - nu)) at a/b = 0. For
    a/b > 10 (b/a < 0.1) c11 grows without bound and a ValueError is raised.
    """
    ratio = _as_float_array("a_over_b", a_over_b)
    nu = _as_float_array("poisson", poisson)
    if not np.all((ratio > 0.0) & np.isfinite(ratio)):
        raise ValueError(f"a_over_b must be finite and > 0, got {a_over_b!r}")
    if not np.all(ratio <= 1.0 / _KALKER_G[0] * (1.0 + 1e-12)):
        raise ValueError(
            f"a_over_b must be <= 10 (b/a >= 0.1, end of Kalker's table), got {a_over_b!r}"
        )
    if not np.all((nu >= 0.0) & (nu <= 0.5)):
        raise ValueError(f"poisson must lie in [0, 0.5] for Kalker's table, got {poisson!r}")

    ratio, nu = np.broadcast_arrays(ratio, nu)
    a_le_b = ratio <= 1.0
    g = np.where(a_le_b, ratio, 1.0 / ratio)
    # c11 at (g, nu_k) for each table column nu_k, shape (..., 3)
    cols = np.stack(
        [
            np.where(
                a_le_b,
                np.interp(g, _KALKER_G_WITH_ZERO, _C11_A_LE_B_WITH_LIMIT[:, k]),
                np.interp(g, _KALKER_G, _C11_A_GE_B[:, k]),
            )
            for k in range(3)
        ],
        axis=-1,
    )
    # Lagrange parabola in 1/c11 through nu = 0, 0.25, 0.5
    w0 = (nu - 0.25) * (nu - 0.5) * 8.0
    w1 = -nu * (nu - 0.5) * 16.0
    w2 = nu * (nu - 0.25) * 8.0
    inv = w0 / cols[..., 0] + w1 / cols[..., 1] + w2 / cols[..., 2]
    return np.asarray(1.0 / inv, dtype=np.float64)


def kalker_longitudinal_stiffness_N(
    wheel_load_N: ArrayLike,
    wheel_radius_m: ArrayLike,
    rail_crown_radius_m: ArrayLike = 0.3,
    wheel_transverse_radius_m: ArrayLike = math.inf,
    E: ArrayLike = 2.1e11,
    nu: ArrayLike = 0.3,
) -> FloatArray:
    """Longitudinal creep stiffness ``G a b c11`` of ONE wheel, N per unit creepage.

    Kalker 1967 / Polach 2005; ellipse from :func:`hertz_semi_axes` (seed 001, Approach 2),
    ``G = E / (2 (1 + nu))``. This is Kalker's linear-theory slope dFx/dxi at zero creepage.

    Relation to Polach (2005): with ``C = 3 G c11 / (8 a)`` the gradient of the tangential
    stress is ``epsilon = (2/3) C pi a^2 b s / (Q mu) = G a b c11 pi s / (4 Q mu)``, i.e.
    ``epsilon = pi * stiffness * s / (4 Q mu)`` with ``s`` the creepage (dimensionless).
    Polach's ``F = (2 Q mu / pi) (epsilon / (1 + epsilon^2) + arctan(epsilon))`` then has
    slope ``dF/ds = stiffness`` at s = 0 (before his reduction factors k_A, k_S).

    Scales as ``Q**STIFFNESS_LOAD_EXPONENT`` (2/3).
    """
    a, b = hertz_semi_axes(
        wheel_load_N,
        wheel_radius_m,
        rail_crown_radius_m,
        wheel_transverse_radius_m,
        youngs_modulus_Pa=E,
        poisson=nu,
    )
    nu_arr = np.asarray(nu, dtype=np.float64)
    G = np.asarray(E, dtype=np.float64) / (2.0 * (1.0 + nu_arr))
    c11 = kalker_c11(a / b, nu_arr)
    return np.asarray(G * a * b * c11, dtype=np.float64)
