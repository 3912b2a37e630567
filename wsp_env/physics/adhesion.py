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


@njit(cache=True, error_model="numpy")
def polach(axi, w, mu0, normal_N, stiff_N, kA, kS, A, B):
    """Polach 2005 law; returns (m, dm/d|xi|, dm/dw). ``stiff_N`` = axle Kalker stiffness Ca."""
    e_bw = math.exp(-B * w)
    mu_w = mu0 * ((1.0 - A) * e_bw + A)
    c = math.pi * stiff_N / (4.0 * normal_N * mu_w)  # eps per unit creepage
    eps = c * axi
    ka_eps = kA * eps
    ks_eps = kS * eps
    den = 1.0 + ka_eps * ka_eps
    h = (2.0 / math.pi) * (ka_eps / den + math.atan(ks_eps))
    dh_deps = (2.0 / math.pi) * (
        kA * (1.0 - ka_eps * ka_eps) / (den * den) + kS / (1.0 + ks_eps * ks_eps)
    )
    m = mu_w * h
    m_xi = mu_w * dh_deps * c
    dmuw_dw = -mu0 * (1.0 - A) * B * e_bw
    # m = mu_w h(c0 / mu_w)  ->  dm/dmu_w = h - eps h'(eps)
    m_w = (h - eps * dh_deps) * dmuw_dw
    return m, m_xi, m_w


@njit(cache=True, error_model="numpy")
def polach_shape(axi, mu_level, normal_N, stiff_N, kA, kS):
    """Rising part of the Polach law at a fixed friction level (no fall-off): (s, ds/d|xi|)."""
    c = math.pi * stiff_N / (4.0 * normal_N * mu_level)
    eps = c * axi
    ka_eps = kA * eps
    ks_eps = kS * eps
    den = 1.0 + ka_eps * ka_eps
    s = (2.0 / math.pi) * (ka_eps / den + math.atan(ks_eps))
    ds = (2.0 / math.pi) * (
        kA * (1.0 - ka_eps * ka_eps) / (den * den) + kS / (1.0 + ks_eps * ks_eps)
    )
    return s, ds * c


@njit(cache=True, error_model="numpy")
def polach_simple(axi, w, mu0, K, k_rozv_per_kmh):
    """Seed 000 Eq. 9; returns (m, dm/d|xi|, dm/dw). DV read in km/h (see module doc)."""
    D = 1.0 + k_rozv_per_kmh * KMH_PER_MPS * w
    E = math.exp(-K * axi * D / mu0)
    m = mu0 * (1.0 - E) / D
    m_xi = K * E
    dm_dD = -m / D + K * axi * E / D
    return m, m_xi, dm_dD * k_rozv_per_kmh * KMH_PER_MPS


@njit(cache=True, error_model="numpy")
def polach_simple_shape(axi, mu_level, K):
    """Seed 000 Eq. 9 without fall-off (K_rozv = 0), normalised: (s, ds/d|xi|)."""
    E = math.exp(-K * axi / mu_level)
    return 1.0 - E, K * E / mu_level


@njit(cache=True, error_model="numpy")
def _saturation(alpha):
    """Seed 002 Eq. 4: Ks * alpha (normalised force) and its derivative in alpha."""
    if alpha <= 3.0:
        return alpha - alpha * alpha / 3.0 + alpha * alpha * alpha / 27.0, (
            1.0 - 2.0 * alpha / 3.0 + alpha * alpha / 9.0
        )
    return 1.0, 0.0


@njit(cache=True, error_model="numpy")
def seed002(axi, mu_c, normal_N, stiff_N, k_red, lam):
    """Seed 002 Eqs. 4, 7, 8 (no hysteresis); returns (m, dm/d|xi|, 0)."""
    c = stiff_N / (mu_c * normal_N)  # alpha per unit creepage
    f, df = _saturation(c * axi)
    xi_lim = 3.0 / c
    if axi <= xi_lim:
        return mu_c * f, mu_c * df * c, 0.0
    e = math.exp(-lam * (axi - xi_lim))
    ka = k_red + (1.0 - k_red) * e
    return mu_c * ka, -mu_c * lam * (1.0 - k_red) * e, 0.0


@njit(cache=True, error_model="numpy")
def seed002_shape(axi, mu_level, normal_N, stiff_N):
    """Seed 002 Eq. 4 saturation alone (K_a = 1), normalised: (s, ds/d|xi|)."""
    c = stiff_N / (mu_level * normal_N)
    f, df = _saturation(c * axi)
    return f, df * c


@njit(cache=True, error_model="numpy")
def creep_law(law, axi, w, mu_level, normal_N, stiff_N, p0, p1, p2, p3):
    """Dispatch to the degraded law ``mu*``. Law parameters ``p0..p3``:

    polach: kA, kS, A, B[s/m];  polach_simple: K, K_rozv[1/(km/h)];  seed002: K_red, lambda.
    """
    if law == LAW_POLACH:
        return polach(axi, w, mu_level, normal_N, stiff_N, p0, p1, p2, p3)
    if law == LAW_POLACH_SIMPLE:
        return polach_simple(axi, w, mu_level, p0, p1)
    return seed002(axi, mu_level, normal_N, stiff_N, p0, p1)


@njit(cache=True, error_model="numpy")
def recovered_shape(law, axi, mu_level, normal_N, stiff_N, p0, p1):
    """The recovered (clean) curve's normalised rising shape ``s(|xi|)`` and its slope."""
    if law == LAW_POLACH:
        return polach_shape(axi, mu_level, normal_N, stiff_N, p0, p1)
    if law == LAW_POLACH_SIMPLE:
        return polach_simple_shape(axi, mu_level, p0)
    return seed002_shape(axi, mu_level, normal_N, stiff_N)


@njit(cache=True, error_model="numpy")
def adhesion(law, axi, w, mu_level, mu_rec, k_w, normal_N, stiff_N, p0, p1, p2, p3):
    """Degraded law blended toward the recovered curve by the filtered removal fraction ``k_w``.

    Returns (m, dm/d|xi|, dm/dw) — see the module docstring for the blend.
    """
    m, m_xi, m_w = creep_law(law, axi, w, mu_level, normal_N, stiff_N, p0, p1, p2, p3)
    if k_w <= 0.0:
        return m, m_xi, m_w
    s, s_xi = recovered_shape(law, axi, mu_rec, normal_N, stiff_N, p0, p1)
    keep = 1.0 - k_w
    return keep * m + k_w * mu_rec * s, keep * m_xi + k_w * mu_rec * s_xi, keep * m_w


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


@njit(cache=True, error_model="numpy")
def creep_curve(law, xi, w, mu_level, mu_rec, k_w, normal_N, stiff_N, p0, p1, p2, p3):
    """Vectorised evaluation for tests and plots: signed mu over arrays ``xi`` and ``w``."""
    out = np.empty_like(xi)
    for i in range(xi.size):
        m, _, _ = adhesion(
            law, abs(xi[i]), w[i], mu_level, mu_rec, k_w, normal_N, stiff_N, p0, p1, p2, p3
        )
        out[i] = m if xi[i] >= 0 else -m
    return out
