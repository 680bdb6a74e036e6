"""The two-mass plant's motion between events: modal closed form and the first-root locator.

Core coordinates (everything but x1 and x4, which only integrate):

* load moving (modes 1, 3; s = −1, +1): z = [x2, φ, ω_m, x3, x5], φ the shaft twist
  θ_m − θ_load [rad], ω_m the motor velocity [rad/s]::

      J·ẋ2   = k·φ + c·(ω_m − x2) − s·(x5 + kc)       (friction on the load, SPEC §2)
      φ̇      = ω_m − x2
      J_m·ω̇_m = x3 − k·φ − c·(ω_m − x2)
      ẋ3     = β3·(u − x3),   ẋ5 = −β5·x5

* load stuck (mode 2): x2 ≡ 0, x5 frozen, z = [φ, ω_m, x3] with the same rotor equations.

Each is ż = A·z + b with b constant (kc, u), so with A = V·Λ·V⁻¹ and w = V⁻¹z, b̃ = V⁻¹b,
every mode evolves as w_i(t) = e^(λ_i t)·w_i + t·φ1(λ_i t)·b̃_i and integrates to
∫w_i = t·φ1(λ_i t)·w_i + t²·φ2(λ_i t)·b̃_i, with φ1(x) = (eˣ − 1)/x, φ2(x) = (eˣ − 1 − x)/x²
summed as series near 0 (so the rigid-body mode λ = 0 and the slow β5 need no special case).
The eigenvalues are 0 (rigid body), −β3, −β5 and the shaft's pair −ζω ± iω√(1 − ζ²);
:class:`~plant.two_mass.params.TwoMassParams` rejects a critically damped shaft (a defective A).

**First roots.** A scalar g(t) = Re Σ_i [a_i·e^(λ_i t) + b_i·t·φ1(λ_i t)] (the load velocity,
ẋ1 = x2 − x4, or ks ∓ the shaft torque k·φ + c·(ω_m − x2)) has g'(t) = Re Σ e^(λ_i t)·d_i,
d_i = λ_i a_i + b_i, and, since every Re λ_i ≤ 0, |g''(t + s)| ≤ M2(t) = Σ |λ_i|·|e^(λ_i t)|·|d_i|
for all s ≥ 0. So σ·g stays positive on [t, t + s*) where s* is the positive root of
σg + σg'·s − ½M2·s² (a proof, not a sample): :func:`first_root` steps by s* from the start,
which can never jump over a root however lightly damped the oscillation, and converges to
the first root quadratically from the safe side (each step is a Newton step with a
curvature margin). It stops when the step falls below 1e-15 s.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

from plant.two_mass.eigen import core_modes
from plant.two_mass.params import TwoMassParams

__all__ = ["decompose", "first_root", "phi1", "NCORE"]

NCORE = 5
# Rows of the decomposition tables: mode 1, mode 3, stuck.
M_BACK, M_FWD, M_STUCK = 0, 1, 2


def core_matrix(mode: int, params: TwoMassParams) -> tuple[np.ndarray, int]:
    """A of the core ż = A·z + b (module docstring) and its size, for mode 1, 2 or 3."""
    a, Jm = params.alpha, params.motor_inertia
    k, c = params.shaft_stiffness, params.shaft_damping
    if mode == 2:
        A = np.array([[0.0, 1.0, 0.0],
                      [-k / Jm, -c / Jm, 1.0 / Jm],
                      [0.0, 0.0, -params.beta3]])
        return A, 3
    s = 1.0 if mode == 3 else -1.0
    A = np.array([[-a * c, a * k, a * c, 0.0, -s * a],
                  [-1.0, 0.0, 1.0, 0.0, 0.0],
                  [c / Jm, -k / Jm, -c / Jm, 1.0 / Jm, 0.0],
                  [0.0, 0.0, 0.0, -params.beta3, 0.0],
                  [0.0, 0.0, 0.0, 0.0, -params.beta5]])
    return A, 5


def decompose(params: TwoMassParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V, V⁻¹, λ) for mode 1, mode 3 and stuck (rows 0, 1, 2), padded to 5 × 5: the closed
    form of :func:`plant.two_mass.eigen.core_modes` (no LAPACK: the same bits on every CPU).

    The rigid-body eigenvalue is exactly 0 and no real part is positive (the shaft pair's is
    −μc/2, the others −β), so the bound of :func:`first_root` holds.
    """
    V = np.zeros((3, NCORE, NCORE), dtype=np.complex128)
    Vi = np.zeros((3, NCORE, NCORE), dtype=np.complex128)
    lam = np.zeros((3, NCORE), dtype=np.complex128)
    a, Jm = params.alpha, params.motor_inertia
    k, c = params.shaft_stiffness, params.shaft_damping
    for row, mode in ((M_BACK, 1), (M_FWD, 3), (M_STUCK, 2)):
        if mode == 2:
            n = 3
            got = core_modes("stuck", a, Jm, k, c, [(params.beta3, (0.0, 1.0 / Jm))])
        else:
            n = 5
            s = 1.0 if mode == 3 else -1.0
            got = core_modes("moving", a, Jm, k, c, [(params.beta3, (0.0, 0.0, 1.0 / Jm)),
                                                     (params.beta5, (-s * a, 0.0, 0.0))])
        if got is None:
            raise ValueError(f"two-mass plant: 1/τ3 or 1/τ5 coincides with a shaft eigenvalue (mode {mode}); "
                             "the modal form is singular")
        vec, vinv, ev = got
        lam[row, :n] = ev
        V[row, :n, :n] = vec
        Vi[row, :n, :n] = vinv
    for arr in (V, Vi, lam):
        arr.flags.writeable = False
    return V, Vi, lam


@njit(cache=True, inline="always")
def _small(x):
    """abs(x) < 0.5, deciding by x.real² + x.imag² away from 0.25 (their relative error is a few
    ulps, far inside the ±1e-3 margin) and by abs (hypot) only near it: the same branch, cheaper."""
    r2 = x.real * x.real + x.imag * x.imag
    if r2 < 0.2499:
        return True
    if r2 > 0.2501:
        return False
    return abs(x) < 0.5


@njit(cache=True, inline="always")
def _tiny(term, total):
    """abs(term) < 1e-18·abs(total), by the squared moduli away from the threshold (relative
    margin 1e-6, far above their few-ulp rounding; a square that underflows is a term below
    1.5e-154 against a total ≥ 0.39 in the series here) and by abs (hypot) only near it."""
    rt = term.real * term.real + term.imag * term.imag
    rs = total.real * total.real + total.imag * total.imag
    if rt < 0.999999e-36 * rs:
        return True
    if rt > 1.000001e-36 * rs:
        return False
    return abs(term) < 1e-18 * abs(total)


@njit(cache=True, inline="always")
def _div_k(a, k):
    """a / k for a complex a and a positive integer k, as numba divides a complex by k + 0j
    (CPython's _Py_c_quot, the |b.real| ≥ |b.imag| branch: ratio = 0/k = +0, denom = k + 0·0 = k),
    without the branch, the ratio's division and the denominator: the same operations on the
    same values (tests/test_two_mass_fast.py)."""
    d = float(k)
    return complex((a.real + a.imag * 0.0) / d, (a.imag - a.real * 0.0) / d)


@njit(cache=True)
def phi1(x):
    """(eˣ − 1)/x for complex x, 1 at 0."""
    if _small(x):
        return _phi1_series(x)
    return (cmath.exp(x) - 1.0) / x




@njit(cache=True, inline="always")
def phi1_e(x, e):
    """:func:`phi1` given e = cmath.exp(x) (np.exp of a complex is numba's cmath.exp): the same
    value, without computing eˣ again where the caller has it."""
    if _small(x):
        return _phi1_series(x)
    return (e - 1.0) / x


@njit(cache=True, inline="always")
def phi2_e(x, e):
    """(eˣ − 1 − x)/x² for complex x (½ at 0) given e = cmath.exp(x), as :func:`phi1_e`."""
    if _small(x):
        return _phi2_series(x)
    return (e - 1.0 - x) / (x * x)


@njit(cache=True, inline="always")
def _phi1_series(x):
    term = 1.0 + 0j
    total = 1.0 + 0j
    for k in range(2, 30):
        term = _div_k(term * x, k)
        total += term
        if _tiny(term, total):
            break
    return total


@njit(cache=True, inline="always")
def _phi2_series(x):
    term = 0.5 + 0j
    total = 0.5 + 0j
    for k in range(3, 32):
        term = _div_k(term * x, k)
        total += term
        if _tiny(term, total):
            break
    return total


@njit(cache=True, _nrt=False)
def _g_fast(ca, cb, lam, al, n, t, want_size):
    """g(t) = Σ Re(a_i·e^(λ_i·t) + b_i·t·φ1(λ_i·t)), g'(t), the bound M2(t) ≥ sup_{s≥0} |g''(t + s)|
    (module docstring) and Σ|terms|, with |λ_i| given (``al``), Σ|terms| only when ``want_size``
    (else 0) and the b-term skipped where b_i = 0: the same bits as the plain sum (a skipped
    product is a signed zero; tests/test_two_mass_fast.py)."""
    g = 0.0
    g1 = 0.0
    m2 = 0.0
    size = 0.0
    for i in range(n):
        l = lam[i]
        e = cmath.exp(l * t)
        if cb[i].real == 0.0 and cb[i].imag == 0.0:
            term = ca[i] * e
        else:
            term = ca[i] * e + cb[i] * (t * phi1_e(l * t, e))
        g += term.real
        if want_size:
            size += abs(term)
        d = e * (l * ca[i] + cb[i])
        g1 += d.real
        m2 += al[i] * abs(d)
    return g, g1, m2, size


@njit(cache=True)
def first_exit(ca, cb, lam, n, lo, hi, horizon):
    """First t in (0, horizon] at which g leaves (lo, hi) [lo < g(0) < hi]: (t, +1 at hi, −1 at lo),
    (inf, 0) if it stays inside; t = −1 if the safe steps did not converge.

    :func:`first_root` for hi − g and g − lo at once: both share g, g' and M2, and each step is
    the smaller of the two safe steps.
    """
    al = np.empty(max(n, 1))
    for i in range(n):
        al[i] = abs(lam[i])
    return first_exit_al(ca, cb, lam, al, n, lo, hi, horizon)


@njit(cache=True, _nrt=False)
def first_exit_al(ca, cb, lam, al, n, lo, hi, horizon):
    """first_exit with |λ_i| in ``al``, compiled without reference counting (allocates nothing); same bits."""
    h, side, _ = first_exit_n(ca, cb, lam, al, n, lo, hi, horizon)
    return h, side


@njit(cache=True, _nrt=False)
def first_exit_n(ca, cb, lam, al, n, lo, hi, horizon):
    """:func:`first_exit_al` and the number of safe steps it evaluated (each a g, g′, M2 over the
    n modal terms: the search's work, counted for the fit's work clock)."""
    t = 0.0
    for it in range(100000):
        g, g1, m2, size = _g_fast(ca, cb, lam, al, n, t, t == 0.0)
        best = math.inf
        side = 0
        for k in range(2):
            sigma = 1.0 if k == 0 else -1.0
            y = (hi - g) if k == 0 else (g - lo)
            y1 = -sigma * g1
            if t == 0.0 and abs(y) <= 1e-14 * (size + abs(hi if k == 0 else lo)):
                y = 0.0
            if y <= 0.0:
                if t > 0.0 or y < 0.0 or y1 < 0.0 or (y1 == 0.0 and -sigma * second_derivative(ca, cb, lam, n, t)[0] <= 0.0):
                    return t, (1 if k == 0 else -1), it + 1
                if y1 == 0.0:
                    y2, m3 = second_derivative(ca, cb, lam, n, t)
                    s = 1.5 * (-sigma * y2) / m3
                else:
                    s = 2.0 * y1 / m2 if m2 > 0.0 else math.inf
            else:
                r = math.sqrt(y1 * y1 + 2.0 * m2 * y)
                if y1 >= 0.0:
                    s = (y1 + r) / m2 if m2 > 0.0 else math.inf
                else:
                    s = 2.0 * y / (r - y1)
            if s < best:
                best = s
                side = 1 if k == 0 else -1
        if t + best >= horizon:
            g, _, _, _ = _g_fast(ca, cb, lam, al, n, horizon, False)
            if g >= hi:
                return horizon, 1, it + 1
            if g <= lo:
                return horizon, -1, it + 1
            return math.inf, 0, it + 1
        if best < 1e-15:
            return t + best, side, it + 1
        t += best
    return -1.0, 0, 100000


@njit(cache=True)
def second_derivative(ca, cb, lam, n, t):
    """g''(t) and M3(t), a bound on |g'''(t + s)| for s >= 0."""
    g2 = 0.0
    m3 = 0.0
    for i in range(n):
        l = lam[i]
        d = cmath.exp(l * t) * (l * ca[i] + cb[i])
        g2 += (l * d).real
        m3 += abs(l) * abs(l) * abs(d)
    return g2, m3


@njit(cache=True)
def first_root(ca, cb, lam, n, sigma, horizon):
    """First t in (0, horizon] with g(t) = 0, where σ·g > 0 just after 0; ``inf`` if none.

    Returns 0 when σ·g(0) < 0 (or = 0, to 1e-14 of the terms' size, and falling): already past the level. Returns −1 if the
    safe steps did not converge within 100000 steps (the caller reports it).

    At a start on the level (σ·g(0) = 0 to 1e-14 of the terms' size) a slope within 1e-14 of its
    terms' size Σ|λ_i·a_i + b_i| counts as 0, and the curvature decides (:func:`first_root_n`).
    Why (issue 25, tenth session): a breakaway with k̄s = k̄c leaves the load at x2 = 0 with
    ẋ2 = (T − kc)/J = 0 exactly, which the modal sum gives as ±1e-15 of rounding. A rounding
    slope below 0 returned a root at 0: the load stopped at once, T > ks by rounding reflected it
    (``interval._velocity_zero``), and it did so at one instant until the 2000-event cap
    (status chatter), where the load in truth slides off with ẍ2 = Ṫ/J > 0 (tests/
    test_two_mass_zeno.py against tests/two_mass_reference.py). Only starts on the level are
    affected, on a noise-free or σ2 = 0 moving segment (the fit's predictions): the benchmark's
    ``compliant`` scenario (σ2 > 0, no disturbance torque) never calls this search.
    """
    al = np.empty(max(n, 1))
    for i in range(n):
        al[i] = abs(lam[i])
    return first_root_al(ca, cb, lam, al, n, sigma, horizon)


@njit(cache=True, _nrt=False)
def first_root_al(ca, cb, lam, al, n, sigma, horizon):
    """first_root with |λ_i| in ``al``, compiled without reference counting (allocates nothing); same bits."""
    return first_root_n(ca, cb, lam, al, n, sigma, horizon)[0]


@njit(cache=True, _nrt=False)
def first_root_n(ca, cb, lam, al, n, sigma, horizon):
    """:func:`first_root_al` and the number of safe steps it evaluated (counted for the fit's work clock)."""
    t = 0.0
    for it in range(100000):
        g, g1, m2, size = _g_fast(ca, cb, lam, al, n, t, t == 0.0)
        y = sigma * g
        y1 = sigma * g1
        if t == 0.0 and abs(y) <= 1e-14 * size:
            y = 0.0           # at the level to rounding (e.g. x2 = 0 at breakaway): the slope decides
            dsize = 0.0
            for i in range(n):
                dsize += abs(lam[i] * ca[i] + cb[i])
            if abs(y1) <= 1e-14 * dsize:
                y1 = 0.0      # the slope too (breakaway at ks = kc: ẋ2 = (T − kc)/J = 0): the curvature decides
        if y <= 0.0:
            if t > 0.0:
                return t, it + 1
            if y < 0.0 or y1 < 0.0:
                return 0.0, it + 1
            if y1 == 0.0:
                # a double zero at the start (e.g. breakaway with ks = kc): the sign of g'' decides;
                # σg ≥ ½σg''·s² − M3·s³/6 > 0 for s < 3σg''/M3
                y2, m3 = second_derivative(ca, cb, lam, n, t)
                y2 = sigma * y2
                if y2 <= 0.0:
                    return 0.0, it + 1
                t = 1.5 * y2 / m3
                continue
        r = math.sqrt(y1 * y1 + 2.0 * m2 * max(y, 0.0))
        if y1 >= 0.0:
            s = (y1 + r) / m2 if m2 > 0.0 else math.inf
        else:
            s = 2.0 * y / (r - y1)
        if t + s >= horizon:
            g, _, _, _ = _g_fast(ca, cb, lam, al, n, horizon, False)
            return (horizon if sigma * g <= 0.0 else math.inf), it + 1
        if s < 1e-15:
            return t + s, it + 1
        t += s
    return -1.0, 100000
