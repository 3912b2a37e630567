"""Wheel–rail creep-force laws and the energy-based adhesion recovery, as scalar numba kernels.

Conventions (per axle, both wheels together):

* creepage ``xi = (V - omega r) / max(V, V_eps)`` (seed 000 Eq. 8), positive when braking;
* sliding speed ``w = |V - omega r|`` in m/s;
* every law returns ``(m, m_xi, m_w)``: the adhesion coefficient *magnitude* ``m = |F_x| / N`` at
  ``|xi|`` and ``w``, and its partial derivatives with respect to ``|xi|`` and ``w``. The signed
  coefficient is ``sign(xi) * m`` (all laws are odd in the creepage).

Laws (``LAW_*`` ids, chosen per vehicle/scenario):

``LAW_POLACH``  Polach 2005 (Wear 258) / seed 001 "Approach 2":
    ``mu(w) = mu0 [(1 - A) exp(-B w) + A]``,
    ``eps = pi Ca |xi| / (4 N mu(w))`` (with ``Ca = 2 G a b c11``, the Kalker stiffness of the
    axle; seed 001: ``eps = 2/3 C pi a^2 b / (Q mu) s`` with ``C = 3 G c11 / (8 a)``, ``Q = N/2``),
    ``m = 2 mu(w) / pi [kA eps / (1 + (kA eps)^2) + arctan(kS eps)]``.
    Slope at zero creepage: ``dF/dxi = (kA + kS)/2 * Ca`` (Kalker's linear theory for kA=kS=1).

``LAW_POLACH_SIMPLE``  seed 000 Eq. 9:
    ``m = mu0 (1 - exp(-K |xi| D / mu0)) / D``, ``D = 1 + K_rozv |DV|``.
    The seed does not give the unit of DV; we read it in **km/h** (the unit of every speed in
    that paper's data): with Table 4's K_rozv ~ 0.03 this makes a 20 km/h slide lose 38% of the
    friction, the size of fall-off the paper's Figs. 5–8 show; read in m/s the loss would be 14%.

``LAW_SEED002``  seed 002 Eqs. 4, 7, 8 (the low-energy degraded law ``mu*``):
    ``alpha = Ca |xi| / (mu_c N)``; ``Ks alpha = alpha - alpha^2/3 + alpha^3/27`` for alpha <= 3,
    else 1 (Eq. 4, saturated Kalker); ``K_a = 1`` for ``|xi| <= xi_lim`` and
    ``K_red + (1 - K_red) exp(-lambda (|xi| - xi_lim))`` beyond (Eq. 7; the seed prints
    ``(1 - K_red)^{-lambda(...)}``, a garbled exponential: read as ``(1 - K_red) e^{...}``, the only
    reading with ``K_a(xi_lim) = 1`` and ``K_a -> K_red``). ``xi_lim`` is where alpha = 3.
    The hysteresis branch of Eq. 7 (memorised values on decreasing creep) is not modelled.

Recovery (seed 002 Eqs. 9–14): the specific sliding power ``W = mu N q`` drives the fraction
``K_W = clip((W - W_lim) / (W_max - W_lim), 0, 1)`` of contaminant removed at the contact; ``K_W``
goes through the second-order lag of Eq. 11 (Tustin, Eq. 13) and blends the degraded curve toward
the recovered one: ``mu = (1 - K_W_f) mu*(xi) + K_W_f mu_rec s(xi)``, where ``s(xi)`` is the
law's rising (saturation) shape at the recovered level, without falling friction. In full
sliding ``s = 1`` and this is exactly Eq. 12 (``mu -> mu_rec``); at zero creepage the force is
zero, as it must be (Eq. 12 read literally would leave a force of ``K_W mu_rec N`` at zero creep
while the filter decays). Filtering ``K_W`` instead of ``mu_nf`` (Eq. 14) gives the same step
response of ``mu`` at steady sliding and keeps the creep force instantaneous. The quantity ``q``
is a documented choice (``REC_BASIS_*``), since the seed's units are ambiguous:

* ``REC_BASIS_RAIL_METRE`` ``q = |xi|`` -> W in J per metre of rail (= N); literal Eq. 10 with
  creep referred to the train speed;
* ``REC_BASIS_WHEEL_METRE`` ``q = |DV| / (omega r)`` -> J per metre of wheel tread, Eq. 9 as
  printed;
* ``REC_BASIS_SLIDING_POWER`` ``q = |DV|`` -> W in watts; W_lim/W_max read as 1.6 / 7.8 kW.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

LAW_POLACH = 0
LAW_POLACH_SIMPLE = 1
LAW_SEED002 = 2
LAW_NAMES = {"polach": LAW_POLACH, "polach_simple": LAW_POLACH_SIMPLE, "seed002": LAW_SEED002}

REC_BASIS_RAIL_METRE = 0
REC_BASIS_WHEEL_METRE = 1
REC_BASIS_SLIDING_POWER = 2
REC_BASIS_NAMES = {
    "rail_metre": REC_BASIS_RAIL_METRE,
    "wheel_metre": REC_BASIS_WHEEL_METRE,
    "sliding_power": REC_BASIS_SLIDING_POWER,
}

KMH_PER_MPS = 3.6


JIT = {"cache": True, "error_model": "numpy", "inline": "always"}
HALF_PI = 0.5 * math.pi
TWO_OVER_PI = 2.0 / math.pi


# The contact enters every law through ``k = Ca / N`` (creep stiffness per unit load) and its
# inverse ``1/k``; both are computed once per control period, when the load is updated, so the
# laws below need at most one division per call.


@njit(**JIT)
def _polach_bracket(eps, kA, kS):
    """h(eps) = 2/pi [kA eps / (1 + (kA eps)^2) + arctan(kS eps)] and dh/deps."""
    ka_eps = kA * eps
    ks_eps = kS * eps
    inv_den = 1.0 / (1.0 + ka_eps * ka_eps)
    inv_ks = 1.0 / (1.0 + ks_eps * ks_eps)
    h = TWO_OVER_PI * (ka_eps * inv_den + math.atan(ks_eps))
    dh = TWO_OVER_PI * (kA * (1.0 - ka_eps * ka_eps) * inv_den * inv_den + kS * inv_ks)
    return h, dh


@njit(**JIT)
def polach(axi, w, mu0, k, kA, kS, A, B):
    """Polach 2005 law; returns (m, dm/d|xi|, dm/dw). ``k`` = axle Kalker stiffness / N."""
    e_bw = math.exp(-B * w)
    mu_w = mu0 * ((1.0 - A) * e_bw + A)
    c = 0.25 * math.pi * k / mu_w  # eps per unit creepage
    eps = c * axi
    h, dh = _polach_bracket(eps, kA, kS)
    dmuw_dw = -mu0 * (1.0 - A) * B * e_bw
    # m = mu_w h(c0 / mu_w)  ->  dm/dmu_w = h - eps h'(eps)
    return mu_w * h, mu_w * dh * c, (h - eps * dh) * dmuw_dw


@njit(**JIT)
def polach_simple(axi, w, mu0, K, k_rozv_per_kmh):
    """Seed 000 Eq. 9; returns (m, dm/d|xi|, dm/dw). DV read in km/h (see module doc)."""
    D = 1.0 + k_rozv_per_kmh * KMH_PER_MPS * w
    inv_D = 1.0 / D
    E = math.exp(-K * axi * D / mu0)
    m = mu0 * (1.0 - E) * inv_D
    dm_dD = (K * axi * E - m) * inv_D
    return m, K * E, dm_dD * k_rozv_per_kmh * KMH_PER_MPS


@njit(**JIT)
def _saturation(alpha):
    """Seed 002 Eq. 4: Ks * alpha (normalised force) and its derivative in alpha."""
    if alpha <= 3.0:
        a3 = alpha * (1.0 / 3.0)
        return alpha * (1.0 - a3 + a3 * a3 * (1.0 / 3.0)), (1.0 - a3) ** 2
    return 1.0, 0.0


@njit(**JIT)
def sliding_falloff(w, A, B):
    """Polach 2005 fall-off of friction with sliding speed: ``g = A + (1 - A) exp(-B w)``, dg/dw.

    ``A = 1`` (or ``B = 0``) switches it off. Applied to the seed 002 law (which has none of its
    own): with A 0.4 (Polach 2005) and B 0.18 s/m it lies inside seed 000 Table 4's measured
    soap fall-off ``1 / (1 + K_rozv DV)``, K_rozv 0.0286-0.0325 per km/h, over 0-20 km/h of
    sliding (DV in km/h), and tends to A at a locked wheel's sliding speeds.
    """
    if A >= 1.0 or B <= 0.0:
        return 1.0, 0.0
    e = math.exp(-B * w)
    return A + (1.0 - A) * e, -(1.0 - A) * B * e


@njit(**JIT)
def _seed002_degraded(axi, mu_c, k, inv_k, k_red, lam):
    """Seed 002 Eqs. 4, 7, 8 (no hysteresis), before the fall-off: (m, dm/d|xi|)."""
    xi_lim = 3.0 * mu_c * inv_k  # alpha = k xi / mu_c reaches 3: the peak mu_c
    if axi <= xi_lim:
        c = k / mu_c  # alpha per unit creepage
        f, df = _saturation(c * axi)
        return mu_c * f, mu_c * df * c
    x = lam * (axi - xi_lim)
    if x > 40.0:  # e^-40 ~ 4e-18: fully on the kinematic level
        return mu_c * k_red, 0.0
    e = math.exp(-x)
    return mu_c * (k_red + (1.0 - k_red) * e), -mu_c * lam * (1.0 - k_red) * e


@njit(**JIT)
def _seed002_clean(axi, mu_level, k, inv_k):
    """The recovered contact before the fall-off: Eq. 4's saturation alone (m, dm/d|xi|)."""
    if axi >= 3.0 * mu_level * inv_k:
        return mu_level, 0.0
    c = k / mu_level
    f, df = _saturation(c * axi)
    return mu_level * f, mu_level * df * c


@njit(**JIT)
def seed002(axi, w, mu_c, k, inv_k, k_red, lam, A, B):
    """Seed 002 Eqs. 4, 7, 8 (no hysteresis) times ``sliding_falloff``; (m, dm/d|xi|, dm/dw)."""
    g, g_w = sliding_falloff(w, A, B)
    m0, m0_xi = _seed002_degraded(axi, mu_c, k, inv_k, k_red, lam)
    return m0 * g, m0_xi * g, m0 * g_w


@njit(**JIT)
def seed002_recovered(axi, w, mu_level, k, inv_k, A, B):
    """The recovered (cleaned) contact of the seed 002 law: Eq. 4's saturation at ``mu_level``
    without Eq. 7's kinetic drop (the contaminant's), times ``sliding_falloff``: (m, m_xi, m_w)."""
    g, g_w = sliding_falloff(w, A, B)
    r0, r0_xi = _seed002_clean(axi, mu_level, k, inv_k)
    return r0 * g, r0_xi * g, r0 * g_w


@njit(**JIT)
def creep_law(law, axi, w, mu_level, k, inv_k, p0, p1, p2, p3):
    """Dispatch to the degraded law ``mu*``. ``k`` = Ca / N, ``inv_k`` = N / Ca. Parameters:

    polach: kA, kS, A, B[s/m];  polach_simple: K, K_rozv[1/(km/h)];
    seed002: K_red, lambda, A, B[s/m] (the last two: ``sliding_falloff``).
    """
    if law == LAW_SEED002:
        return seed002(axi, w, mu_level, k, inv_k, p0, p1, p2, p3)
    if law == LAW_POLACH:
        return polach(axi, w, mu_level, k, p0, p1, p2, p3)
    return polach_simple(axi, w, mu_level, p0, p1)


@njit(**JIT)
def recovered_curve(law, axi, w, mu_rec, k, inv_k, p0, p1, p2, p3):
    """The recovered curve at level ``mu_rec``: the law's rising shape and its sliding-speed
    fall-off (a cleaned rail still loses friction with sliding speed), without the seed 002
    law's kinetic drop K_red. Returns (m, dm/d|xi|, dm/dw)."""
    if law == LAW_SEED002:
        return seed002_recovered(axi, w, mu_rec, k, inv_k, p2, p3)
    return creep_law(law, axi, w, mu_rec, k, inv_k, p0, p1, p2, p3)


@njit(**JIT)
def adhesion(law, axi, w, mu_level, mu_rec, k_w, k, inv_k, p0, p1, p2, p3):
    """Degraded law blended toward the recovered curve by the filtered removal fraction ``k_w``.

    Returns (m, dm/d|xi|, dm/dw) — see the module docstring for the blend.
    """
    if law == LAW_SEED002:  # both curves share the fall-off: blend first, one exp
        g, g_w = sliding_falloff(w, p2, p3)
        b, b_xi = _seed002_degraded(axi, mu_level, k, inv_k, p0, p1)
        if k_w > 0.0:
            r0, r0_xi = _seed002_clean(axi, mu_rec, k, inv_k)
            keep = 1.0 - k_w
            b, b_xi = keep * b + k_w * r0, keep * b_xi + k_w * r0_xi
        return b * g, b_xi * g, b * g_w
    m, m_xi, m_w = creep_law(law, axi, w, mu_level, k, inv_k, p0, p1, p2, p3)
    if k_w <= 0.0:
        return m, m_xi, m_w
    r, r_xi, r_w = recovered_curve(law, axi, w, mu_rec, k, inv_k, p0, p1, p2, p3)
    keep = 1.0 - k_w
    return keep * m + k_w * r, keep * m_xi + k_w * r_xi, keep * m_w + k_w * r_w


PEAK_GRID = 64
PEAK_XI_MIN, PEAK_XI_MAX = 1e-4, 0.6


@njit(cache=True, error_model="numpy")
def adhesion_value(law, axi, w, mu_level, mu_rec, k_w, k, inv_k, p0, p1, p2, p3):
    """``adhesion(...)[0]`` as a called (not inlined) function: ``peak_adhesion`` evaluates the
    curve at four places, and the whole law library inlined at each made it the slowest kernel
    to compile (the same floating-point operations either way)."""
    return adhesion(law, axi, w, mu_level, mu_rec, k_w, k, inv_k, p0, p1, p2, p3)[0]


@njit(cache=True, error_model="numpy")
def peak_adhesion(law, level, mu_rec, kw, k, inv_k, v, p0, p1, p2, p3):
    """Creepage and coefficient at the peak of the curve ``mu(xi, DV = xi V)`` at speed ``v``.

    A log grid of creepages (1e-4 .. 0.6) refined by a parabola through the best three points.
    """
    log_lo = math.log(PEAK_XI_MIN)
    step = (math.log(PEAK_XI_MAX) - log_lo) / (PEAK_GRID - 1)
    best_i = 0
    best = -1.0
    for i in range(PEAK_GRID):
        xi = math.exp(log_lo + i * step)
        m = adhesion_value(law, xi, xi * v, level, mu_rec, kw, k, inv_k, p0, p1, p2, p3)
        if m > best:
            best = m
            best_i = i
    log_xi = log_lo + best_i * step
    if 0 < best_i < PEAK_GRID - 1:
        x0 = math.exp(log_xi - step)
        x2 = math.exp(log_xi + step)
        a = adhesion_value(law, x0, x0 * v, level, mu_rec, kw, k, inv_k, p0, p1, p2, p3)
        c = adhesion_value(law, x2, x2 * v, level, mu_rec, kw, k, inv_k, p0, p1, p2, p3)
        den = a - 2.0 * best + c
        if den < 0.0:
            log_xi += 0.5 * step * (a - c) / den
    xi = math.exp(log_xi)
    m = adhesion_value(law, xi, xi * v, level, mu_rec, kw, k, inv_k, p0, p1, p2, p3)
    if m < best:
        return math.exp(log_lo + best_i * step), best
    return xi, m


def tustin_second_order(tau_s: float, zeta: float, dt_s: float) -> np.ndarray:
    """Coefficients ``[b0, b1, b2, a1, a2]`` of seed 002 Eq. 11 discretised by Eq. 13 (Tustin).

    ``H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)``, unit DC gain.
    """
    if tau_s <= 0 or dt_s <= 0 or zeta <= 0:
        raise ValueError("recovery filter needs tau_s > 0, zeta > 0 and dt_s > 0")
    k = 2.0 / dt_s
    t2 = (tau_s * k) ** 2
    t1 = 2.0 * zeta * tau_s * k
    a0 = t2 + t1 + 1.0
    return np.array([1.0 / a0, 2.0 / a0, 1.0 / a0, (2.0 - 2.0 * t2) / a0, (t2 - t1 + 1.0) / a0])


@njit(**JIT)
def creep_curve(law, xi, w, mu_level, mu_rec, k_w, normal_N, stiff_N, p0, p1, p2, p3):
    """Vectorised evaluation for tests and plots: signed mu over arrays ``xi`` and ``w``."""
    out = np.empty_like(xi)
    k = stiff_N / normal_N
    for i in range(xi.size):
        m, _, _ = adhesion(law, abs(xi[i]), w[i], mu_level, mu_rec, k_w, k, 1.0 / k, p0, p1, p2, p3)
        out[i] = m if xi[i] >= 0 else -m
    return out
