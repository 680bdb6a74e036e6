"""Discrete transfer functions of the linear designs in plain float arithmetic.

The linear designs (``linear`` and the peers built on it) used python-control for the ZOH
discretization, the products of sections and the margins. Those go through OpenBLAS and LAPACK
(``expm``, ``np.poly``, ``np.convolve``'s ``ddot``, ``np.roots``), whose kernels round in their own
order per CPU, so a design's last bits — its gain, and every row after it — depended on the
machine (docs/results.md, "Reproducibility across machines"). Here every number a design
depends on is a closed form or a sum in a fixed order over Python floats (``math``, ``cmath``):

* :func:`zoh_gimbal` — Pd(z) of G(s) = 1/(J·s²·(τ3·s + 1)) with a zero-order hold, in closed
  form (the partial fractions 1/s³ − τ/s² + τ²/s − τ²/(s + 1/τ) of G(s)/s, step-invariant
  z-transforms), with the cancellation-free remainders of :mod:`plant.expfun` — also more
  accurate than ``ct.sample_system`` (whose numerator keeps ~9 digits here);
* :func:`tustin_first_order` — (b0·s + b1)/(a0·s + a1) with s = k·(z − 1)/(z + 1),
  k = ω/tan(ωτs/2) (prewarped at ω), normalised to a monic denominator;
* :func:`poly_mul`, :func:`poly_add`, :func:`poly_eval` — coefficient lists, highest power first
  (numpy's order), products summed left to right, Horner in Python complex;
* :func:`margins` — gain crossovers (|L| = 1) and phase crossovers (Im L = 0, Re L ≤ 0) of
  L(e^{jωτs}) on (0, π/τs), bracketed on a dense grid and refined by Brent's method on the scalar
  form; the phase margin at each gain crossover and 1/|L| at each phase crossover, with
  python-control's conventions (``stability_margins(..., returnall=True)``, method ``poly``).
  ``tests/test_discrete_tf.py`` checks them against python-control and closed forms.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from scipy.optimize import brentq

from plant.expfun import e1, e3

__all__ = ["zoh_gimbal", "tustin_first_order", "poly_mul", "poly_add", "poly_eval", "margins"]

Poly = tuple[float, ...]


def zoh_gimbal(inertia: float, tau3: float, ts: float) -> tuple[Poly, Poly]:
    """(num, den) of Pd(z) = (1 − z⁻¹)·Z{G(s)/s}, G(s) = 1/(J·s²·(τ3·s + 1)), u [ozf·in] → c [rad].

    With x = τs/τ3 and p = e^(−x): den = (z − 1)²·(z − p) and, over J/τ3²,
    num = e3(x)·z² + b1·z − p·e3(−x)… written as b0 = e3(x), b2 = p·(e^x − 1 − x − x²/2) =
    −p·e3(−x), b1 = x²·e1(x) − b0 − b2 (so that num(1) = x²·(1 − p), the DC condition).
    """
    x = ts / tau3
    p = math.exp(-x)
    scale = tau3 * tau3 / inertia
    b0 = e3(x)
    b2 = -p * e3(-x)
    b1 = x * x * e1(x) - b0 - b2
    num = (scale * b0, scale * b1, scale * b2)
    den = (1.0, -(2.0 + p), 1.0 + 2.0 * p, -p)
    return num, den


def tustin_first_order(num: tuple[float, float], den: tuple[float, float], ts: float,
                       omega: float) -> tuple[Poly, Poly]:
    """(num, den) in z of (b0·s + b1)/(a0·s + a1), Tustin prewarped at ``omega`` [rad/s]:
    s = k·(z − 1)/(z + 1), k = ω/tan(ω·τs/2); the denominator made monic."""
    b0, b1 = float(num[0]), float(num[1])
    a0, a1 = float(den[0]), float(den[1])
    k = omega / math.tan(omega * ts / 2.0)
    lead = a0 * k + a1
    return ((b0 * k + b1) / lead, (b1 - b0 * k) / lead), (1.0, (a1 - a0 * k) / lead)


def poly_mul(a, b) -> Poly:
    """The product of two coefficient lists (highest power first), each coefficient summed in
    order of the first factor's index."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    out = [0.0] * (len(a) + len(b) - 1)
    for i, ai in enumerate(a):
        for j, bj in enumerate(b):
            out[i + j] += ai * bj
    return tuple(out)


def poly_add(a, b) -> Poly:
    """The sum of two coefficient lists (highest power first), aligned at the constant term."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    n = max(len(a), len(b))
    a, b = [0.0] * (n - len(a)) + a, [0.0] * (n - len(b)) + b
    return tuple(x + y for x, y in zip(a, b))


def poly_eval(c, z: complex) -> complex:
    """c(z) by Horner's rule in Python complex arithmetic."""
    acc = 0j
    for v in c:
        acc = acc * z + float(v)
    return acc


def _response(num, den, omega: float, ts: float) -> complex:
    z = cmath.exp(1j * omega * ts)
    return poly_eval(num, z) / poly_eval(den, z)


_GRID_POINTS = 8192
_OMEGA_MIN = 1e-3   # rad/s: below it the double integrator's phase is −180° to within ~1e-5°


def _mod360(x: float) -> float:
    """x mod 360 in [0, 360), as numpy's ``remainder(x, 360.)``."""
    r = math.fmod(x, 360.0)
    return r + 360.0 if r < 0.0 else r


def margins(num, den, ts: float) -> tuple[list[float], list[float], list[float], list[float]]:
    """(gm, pm, w_pc, w_gc) of L(z) = num/den at z = e^{jωτs}, ω in (0, π/τs), sorted by ω.

    ``gm`` = 1/|L| at the phase crossovers ``w_pc`` (Im L = 0 with Re L ≤ 0); ``pm`` [deg] =
    (∠L mod 360°) − 180° at the gain crossovers ``w_gc`` (|L| = 1). The crossings are bracketed
    by sign changes on a geometric grid of 8192 frequencies from 1e-3 rad/s to π/τs (numpy, for the
    signs only) and refined with ``scipy.optimize.brentq`` on the scalar forms (Python floats), so
    the returned values do not depend on a BLAS kernel.
    """
    nyquist = math.pi / ts
    grid = np.geomspace(_OMEGA_MIN, nyquist, _GRID_POINTS)[:-1]
    z = np.exp(1j * grid * ts)
    resp = np.polyval(np.asarray(num, dtype=float), z) / np.polyval(np.asarray(den, dtype=float), z)
    log_mag = np.log(np.abs(resp))
    imag = resp.imag

    def mag_minus_one(w: float) -> float:
        return math.log(abs(_response(num, den, w, ts)))

    def imag_part(w: float) -> float:
        return _response(num, den, w, ts).imag

    w_gc = [brentq(mag_minus_one, float(grid[i]), float(grid[i + 1]), xtol=1e-14, rtol=4 * 2.0 ** -52)
            for i in np.nonzero(np.diff(np.sign(log_mag)) != 0)[0]]
    w_pc = []
    for i in np.nonzero(np.diff(np.sign(imag)) != 0)[0]:
        w = brentq(imag_part, float(grid[i]), float(grid[i + 1]), xtol=1e-14, rtol=4 * 2.0 ** -52)
        if _response(num, den, w, ts).real <= 0.0:
            w_pc.append(w)
    gm = [1.0 / abs(_response(num, den, w, ts)) for w in w_pc]
    pm = [_mod360(math.degrees(cmath.phase(_response(num, den, w, ts)))) - 180.0 for w in w_gc]
    return gm, pm, w_pc, w_gc
