"""PID with position-only friction observer and adaptive Coulomb estimate, ``observer-pid``
(a peer; SPEC §10).

Sources: the classical disturbance observer (a Luenberger observer of the input-referred
disturbance torque, e.g. Ohnishi's DOB; here the position-only form with the torque model), and
B. Friedland and Y.-J. Park, "On adaptive friction compensation", IEEE Trans. Automatic Control
37(10) (1992) 1609–1612, for the adaptive Coulomb estimate k̂c driven by the observed friction
while the axis moves.

Model (from the measured error y = x1 + w1 [rad], the commanded level u [ozf·in] and the
nominal J, τ3 only — no friction model):

    ÿ = (x3 − d)/J,   ẋ3 = (u − x3)/τ3,   ḋ = 0

(ẋ4 ≈ 0, so the error obeys the shaft's equation; d [ozf·in] is the friction torque plus all
other disturbances). Discretized exactly with a zero-order hold (closed form), x3 is a known state
driven by u; the observer on (y, ẏ, d) is

    ẑ(n+1) = Φ ẑ(n) + Γ u(n) + L·(y(n) − ŷ(n))

with L placed by Ackermann's formula so that the estimation error has the poles
{e^(−ωo·τs), e^(−3ωo·τs), e^(−4ωo·τs)}: the disturbance estimate follows a step in d with the
dominant first-order time constant 1/ωo (the observer bandwidth ωo, the knob).

Design rule:

* the PID of ``reset-pid`` (``design_linear(integral=True)``, the same crossover rules as
  ``linear``), without reset;
* disturbance-observer compensation, always: u = clip(u_pid + d̂, ±u_max) on the linear
  amplifier. While the axis sticks the observed "disturbance" is the friction reaction, so d̂
  follows the applied torque and the loop gains fast integral action: the static friction in
  the reference's direction is fed forward by the observer itself (a separate Coulomb
  feedforward would count it twice);
* stiction → Coulomb at breakaway: when the observer's velocity x̂2 = ẏ̂ + x̂4 (x̂4 the
  stuck-sample average of −ẏ̂ of the least-squares slope, as in ``reset-pid``) first exceeds
  ``stick_velocity``, the friction drops from the static level that d̂ holds to the Coulomb
  level, so d̂ := k̂c·sign(x̂2) (``breakaway_jump``);
* adaptive Coulomb estimate (after Friedland & Park): while moving,
  k̂c ← k̂c + (τs/τc)·(sign(x̂2)·d̂ − k̂c), starting from ``initial_coulomb_factor``·k̄c.

Knob: the observer bandwidth ωo [rad/s]. Default chosen by the sweep in docs/tuning.md
(thesis scenario, seeds 0–4 only).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numba import njit

from controllers.base import register
from controllers.discrete_tf import poly_mul
from controllers.pid import P_NWIN, P_STICK, S_V, S_X4, pid_hold, pid_observe, pid_proportional, py_max
from controllers.reset_pid import PidFrictionOptions, _PidFrictionBase, _positive
from plant.drive import DriveCommand
from plant.expfun import e1, e2, e3
from plant.params import PlantParams

__all__ = ["ObserverPidOptions", "ObserverPidController", "DisturbanceObserver"]


class DisturbanceObserver:
    """Position-only observer of (y, ẏ, x3, d) with the d-error dominant pole at e^(−ωo·τs).

    Parameters
    ----------
    inertia, motor_time_constant, sample_period : float
        J [ozf·in·s²], τ3 [s], τs [s] (nominal).
    bandwidth : float
        ωo [rad/s].
    fast_factors : tuple of float
        The other two error poles sit at e^(−k·ωo·τs) for these k.
    """

    def __init__(self, inertia: float, motor_time_constant: float, sample_period: float,
                 bandwidth: float, fast_factors: tuple[float, float] = (3.0, 4.0)) -> None:
        (self.Phi, self.Gamma, self.L, self.poles, self.error_matrix,
         self._update) = _observer_design(float(inertia), float(motor_time_constant), float(sample_period),
                                          float(bandwidth), tuple(float(k) for k in fast_factors))
        self._z = (0.0, 0.0, 0.0, 0.0)

    @property
    def z(self) -> np.ndarray:
        """ẑ = (y, ẏ, x3, d) as a fresh array (a copy: assign :attr:`disturbance` to change d̂)."""
        return np.array(self._z)

    @property
    def disturbance(self) -> float:
        """d̂ [ozf·in] (settable: the breakaway jump)."""
        return self._z[3]

    @disturbance.setter
    def disturbance(self, value: float) -> None:
        z = self._z
        self._z = (z[0], z[1], z[2], float(value))

    @property
    def velocity(self) -> float:
        """ẏ̂ [rad/s]."""
        return self._z[1]

    def update(self, y: float, u: float) -> None:
        """ẑ(n+1) = Φ ẑ(n) + Γ u(n) + L (y(n) − ŷ(n))."""
        self._z = self._update(self._z, y, u)


@functools.lru_cache(maxsize=64)
def _observer_design(J: float, tau3: float, ts: float, bandwidth: float,
                     fast_factors: tuple[float, float]) -> tuple:
    """(Φ, Γ, L, poles, A − L·C, step) of :class:`DisturbanceObserver` (cached; the arrays are
    read-only). Φ, Γ in closed form (:func:`_zoh`), L by Ackermann's formula in fixed-order float
    arithmetic (:func:`_ackermann`): no BLAS or LAPACK, so the same bits on every machine."""
    Phi, Gamma = _zoh(J, tau3, ts)
    idx = [0, 1, 3]                              # observed (y, ẏ, d); x3 is known
    A = Phi[np.ix_(idx, idx)]
    C = np.array([1.0, 0.0, 0.0])
    poles = np.array([math.exp(-f * bandwidth * ts) for f in (1.0, *fast_factors)])
    L3 = _ackermann(A, C, poles)
    L = np.zeros(4)
    L[idx] = L3
    error_matrix = A - np.outer(L3, C)           # ε(n+1) = (A − L·C)·ε(n): single products
    for a in (Phi, Gamma, L, poles, error_matrix):
        a.flags.writeable = False
    return Phi, Gamma, L, poles, error_matrix, _observer_step(Phi, Gamma, L)


def _observer_step(Phi: np.ndarray, Gamma: np.ndarray, L: np.ndarray):
    """``step(z, y, u) -> z'`` = Φ·z + Γ·u + L·(y − z0) in straight-line float arithmetic.

    The same float operations, in the same order, as the numpy expression
    ``Phi @ z + Gamma * u + L * (y - z[0])`` on this machine's numpy (4 × 4 matrix–vector
    product summed as (Φi0·z0 + Φi2·z2) + (Φi1·z1 + Φi3·z3), no fused multiply–add), so the
    numbers are bit-identical to it (whole recorded runs compared; tests/test_peer_kernels.py
    checks the form to 1e−12). Products with an exact 0
    coefficient are dropped (x + 0·z = x but for the sign of a zero result) and an exact 1
    coefficient is not multiplied. ~1 µs per sample against ~4 µs for the numpy form.
    """
    names: dict[str, float] = {}

    def term(kind: str, i: int, j: int | None, coef: float, var: str) -> str | None:
        if coef == 0.0:
            return None
        if coef == 1.0:
            return var
        key = f"{kind}{i}{'' if j is None else j}"
        names[key] = float(coef)
        return f"{key} * {var}"

    rows = []
    for i in range(4):
        parts = []
        for pair in ((0, 2), (1, 3)):
            ts = [t for t in (term("p", i, j, Phi[i, j], f"z{j}") for j in pair) if t is not None]
            if ts:
                parts.append(ts[0] if len(ts) == 1 else f"({ts[0]} + {ts[1]})")
        mat = " + ".join(parts) if parts else "0.0"
        if len(parts) == 2:
            mat = f"({mat})"
        g = term("g", i, None, Gamma[i], "u")
        k = term("l", i, None, L[i], "e")
        expr = mat
        for extra in (g, k):                 # (Φ·z)i + Γi·u, then + Li·e, as numpy adds them
            if extra is not None:
                expr = f"({expr} + {extra})"
        rows.append(expr)
    source = ("def step(z, y, u):\n    z0, z1, z2, z3 = z\n    e = y - z0\n"
              f"    return ({', '.join(rows)},)\n")
    scope: dict = dict(names)
    exec(compile(source, "<disturbance observer>", "exec"), scope)   # noqa: S102 — numbers only, built here
    scope["step"].source = source
    return scope["step"]


def _zoh(J: float, tau3: float, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) of the state (y, ẏ, x3, d) under ÿ = (x3 − d)/J, ẋ3 = (u − x3)/τ3, ḋ = 0 over one
    sample τs with u held: [Φ Γ; 0 1] = expm([F G; 0 0]·τs), in closed form. With x = τs/τ3 and
    the remainders e1..e3 of :mod:`plant.expfun`: x3' = e^(−x)·x3 + e1·u;
    ẏ' = ẏ + (τ3·e1·x3 + τ3·e2·u − τs·d)/J; y' = y + τs·ẏ + (τ3²·e2·x3 + τ3²·e3·u − τs²/2·d)/J."""
    x = ts / tau3
    a1, a2, a3 = e1(x), e2(x), e3(x)
    Phi = np.array([[1.0, ts, tau3 * tau3 * a2 / J, -0.5 * ts * ts / J],
                    [0.0, 1.0, tau3 * a1 / J, -ts / J],
                    [0.0, 0.0, math.exp(-x), 0.0],
                    [0.0, 0.0, 0.0, 1.0]])
    Gamma = np.array([tau3 * tau3 * a3 / J, tau3 * a2 / J, a1, 0.0])
    return Phi, Gamma


def _dot(xs, ys) -> float:
    """Σ x·y summed left to right (not ``sum``, which compensates from Python 3.12 on)."""
    acc = 0.0
    for x, y in zip(xs, ys):
        acc += x * y
    return acc


def _matmul(a: list[list[float]], b: list[list[float]]) -> list[list[float]]:
    """a·b of small row lists, each entry summed left to right."""
    cols = [[row[j] for row in b] for j in range(len(b[0]))]
    return [[_dot(a_row, col) for col in cols] for a_row in a]


def _solve(m: list[list[float]], rhs: list[float]) -> list[float]:
    """m⁻¹·rhs by Gaussian elimination with partial pivoting (a few rows)."""
    n = len(m)
    a = [list(row) + [r] for row, r in zip(m, rhs)]
    for c in range(n):
        piv = max(range(c, n), key=lambda r: abs(a[r][c]))
        if a[piv][c] == 0.0:
            raise ValueError("observer design: the pair (A, C) is not observable")
        a[c], a[piv] = a[piv], a[c]
        for r in range(c + 1, n):
            f = a[r][c] / a[c][c]
            a[r] = [v - f * w for v, w in zip(a[r], a[c])]
    out = [0.0] * n
    for r in range(n - 1, -1, -1):
        out[r] = (a[r][n] - _dot(a[r][r + 1:n], out[r + 1:n])) / a[r][r]
    return out


def _ackermann(A: np.ndarray, C: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Observer gain L with eig(A − L·C) = poles (Ackermann's formula on the dual system):
    L = φ(A)·O⁻¹·eₙ, φ(s) = Π (s − pᵢ), O = [C; C·A; …; C·Aⁿ⁻¹], in fixed-order float arithmetic."""
    n = A.shape[0]
    a = [[float(v) for v in row] for row in A]
    coeffs = (1.0,)
    for p in poles:                                  # s^n + c1 s^(n−1) + … + cn
        coeffs = poly_mul(coeffs, (1.0, -float(p)))
    powers = [[[float(i == j) for j in range(n)] for i in range(n)]]
    for _ in range(n):
        powers.append(_matmul(powers[-1], a))
    phi = [[_dot(coeffs, [powers[n - k][i][j] for k in range(n + 1)]) for j in range(n)] for i in range(n)]
    c_row = [[float(v) for v in C]]
    obs = [_matmul(c_row, powers[k])[0] for k in range(n)]
    w = _solve(obs, [float(k == n - 1) for k in range(n)])
    return np.array(_matmul(phi, [[v] for v in w])).ravel()


# observer-pid's own entries of s and p (after controllers.pid.PidLayout's shared ones)
_OS_Z, _OS_KC, _OS_MOVING, _OS_BREAKAWAYS, _OS_WAS_MOVING, _OS_UCOMP = 0, 4, 5, 6, 7, 8
_OP_PHI, _OP_GAMMA, _OP_L, _OP_ALPHA_KC, _OP_JUMP = 0, 16, 20, 24, 25
_OS0, _OP0 = S_V + 1, P_NWIN + 1


@njit(cache=True)
def _term(coef, var):
    # one product of _observer_step's straight-line code: an exact 1 is not multiplied
    return var if coef == 1.0 else coef * var


@njit(cache=True)
def observer_update(z, y, u, Phi, Gamma, L):
    """z := Φ·z + Γ·u + L·(y − z0) in place, in :func:`_observer_step`'s order of operations
    (each row (Φi0·z0 + Φi2·z2) + (Φi1·z1 + Φi3·z3), then + Γi·u, then + Li·e, with e = y − z0;
    products with an exact 0 coefficient dropped, an exact 1 not multiplied). ``Phi`` is
    row-major, 16 entries."""
    z0, z1, z2, z3 = z[0], z[1], z[2], z[3]
    zz = (z0, z1, z2, z3)
    e = y - z0
    for i in range(4):
        have = False
        acc = 0.0
        for pair in range(2):
            ja, jb = pair, pair + 2
            ca, cb = Phi[4 * i + ja], Phi[4 * i + jb]
            if ca != 0.0 and cb != 0.0:
                part = _term(ca, zz[ja]) + _term(cb, zz[jb])
            elif ca != 0.0:
                part = _term(ca, zz[ja])
            elif cb != 0.0:
                part = _term(cb, zz[jb])
            else:
                continue
            if have:
                acc = acc + part
            else:
                acc = part
                have = True
        if Gamma[i] != 0.0:
            acc = acc + _term(Gamma[i], u)
        if L[i] != 0.0:
            acc = acc + _term(L[i], e)
        z[i] = acc


@njit(cache=True)
def _observer_pid_step(s, p, y, offs, levs):
    """:class:`ObserverPidController`'s step on (s, p): slope and x̂4, breakaway and k̂c, the PID
    plus d̂, the observer update with the held level."""
    pid_observe(s, p, y)
    z = s[_OS0 + _OS_Z:_OS0 + _OS_Z + 4]
    x2_hat = z[1] + s[S_X4]
    moving = abs(x2_hat) > p[P_STICK]
    if moving:
        if s[_OS0 + _OS_WAS_MOVING] == 0.0 and p[_OP0 + _OP_JUMP] != 0.0:
            z[3] = math.copysign(s[_OS0 + _OS_KC], x2_hat)     # static → Coulomb level at breakaway
            s[_OS0 + _OS_BREAKAWAYS] += 1.0
        s[_OS0 + _OS_MOVING] += 1.0
        kc = s[_OS0 + _OS_KC]                                   # after Friedland & Park
        kc = kc + p[_OP0 + _OP_ALPHA_KC] * (math.copysign(z[3], x2_hat) - kc)
        s[_OS0 + _OS_KC] = py_max(kc, 0.0)
    s[_OS0 + _OS_WAS_MOVING] = 1.0 if moving else 0.0
    u_comp = z[3]
    s[_OS0 + _OS_UCOMP] = u_comp
    level = pid_hold(s, p, pid_proportional(s, p, y), u_comp)
    observer_update(z, y, level, p[_OP0 + _OP_PHI:_OP0 + _OP_PHI + 16], p[_OP0 + _OP_GAMMA:_OP0 + _OP_GAMMA + 4],
                    p[_OP0 + _OP_L:_OP0 + _OP_L + 4])
    offs[0] = 0.0
    levs[0] = level
    return 1


@dataclass(frozen=True)
class ObserverPidOptions(PidFrictionOptions):
    """Options of :class:`ObserverPidController`: :class:`PidFrictionOptions` plus

    Attributes
    ----------
    observer_bandwidth : float
        ωo [rad/s], the dominant pole of the disturbance estimate; in (0, π/τs) (checked at
        reset).
    coulomb_tau : float
        Time constant τc of the adaptive Coulomb estimate while moving [s].
    initial_coulomb_factor : float
        k̂c starts at this × the nominal k̄c [–], ≥ 0.
    breakaway_jump : bool
        Set d̂ := k̂c·sign(x̂2) when motion is first detected.

    The inherited ``coulomb_feedforward`` and ``feedforward_min_velocity`` are not used: the
    observer supplies the static level.
    """

    observer_bandwidth: float = 120.0
    coulomb_tau: float = 1.0
    initial_coulomb_factor: float = 0.5
    breakaway_jump: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive("observer_bandwidth", self.observer_bandwidth)
        _positive("coulomb_tau", self.coulomb_tau)
        v = self.initial_coulomb_factor
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"initial_coulomb_factor must be a finite number >= 0, got {v!r}")
        if not isinstance(self.breakaway_jump, bool):
            raise ValueError(f"breakaway_jump must be a bool, got {self.breakaway_jump!r}")


@register("observer-pid")
class ObserverPidController(_PidFrictionBase):
    """PID plus friction compensation from a position-only disturbance observer and an adaptive
    Coulomb estimate (Friedland & Park 1992). Options: :class:`ObserverPidOptions`. Knob:
    ``observer_bandwidth`` [rad/s]. Counter: ``breakaways`` (detected stick → slip, where d̂
    jumps to the Coulomb estimate). Its report series: k̂c against the true kc."""

    description = "PID + position-only disturbance observer + adaptive Coulomb (Friedland & Park 1992)"
    Options = ObserverPidOptions
    presets = MappingProxyType({
        "default": ObserverPidOptions(),
        "no-adaptation": dataclasses.replace(ObserverPidOptions(), coulomb_tau=1e9,
                                             initial_coulomb_factor=1.0),
    })
    counter = "breakaways"
    knobs = MappingProxyType({"observer_bandwidth": (5.0, 10.0, 20.0, 30.0, 50.0, 80.0, 120.0, 160.0,
                                                     250.0)})

    _compiled_step = staticmethod(_observer_pid_step)
    _n_own_state, _n_own_params = 9, 26

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design the PID and the observer for ``params``; k̂c from the nominal k̄c."""
        o = self.options
        if not o.observer_bandwidth < math.pi / params.sample_period:
            raise ValueError(f"observer_bandwidth must be < π/τs = {math.pi / params.sample_period:.4g} "
                             f"rad/s, got {o.observer_bandwidth!r}")
        super().reset(params, rng)
        self.observer = obs = DisturbanceObserver(params.inertia, params.motor_time_constant,
                                                  params.sample_period, o.observer_bandwidth)
        s, p, i = self._s, self._p, self._own_p
        s[self._own(_OS_KC)] = o.initial_coulomb_factor * params.coulomb
        p[i(_OP_PHI):i(_OP_PHI) + 16] = obs.Phi.ravel()
        p[i(_OP_GAMMA):i(_OP_GAMMA) + 4] = obs.Gamma
        p[i(_OP_L):i(_OP_L) + 4] = obs.L
        p[i(_OP_ALPHA_KC)], p[i(_OP_JUMP)] = params.sample_period / o.coulomb_tau, o.breakaway_jump

    def step(self, y: float) -> DriveCommand:
        """u(n) = clip(u_pid + d̂); at breakaway d̂ := k̂c·sign(x̂2) (see module docstring;
        :func:`_observer_pid_step`)."""
        return super().step(y)

    kc_hat = property(lambda self: float(self._s[self._own(_OS_KC)]), doc="k̂c [ozf·in].")
    d_hat = property(lambda self: float(self._s[self._own(_OS_Z + 3)]), doc="d̂ [ozf·in].")

    def internals(self) -> dict[str, float]:
        s = self._s
        return {"u_linear": self._level, "integrator": -self.pid.q, "compensation": float(s[self._own(_OS_UCOMP)]),
                "d_hat": self.d_hat, "kc_hat": self.kc_hat, "x4_hat": self.x4_hat,
                "stuck": float(self.stuck)}

    def report_series(self, t: np.ndarray, warmup_s: float) -> dict[str, np.ndarray]:
        """No extra series: the figures use the recorded internals (k̂c → ``kc_hat_pct``)."""
        return {}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "design"):
            return {}
        out = self.design.summary()
        s = self._s
        out.update(observer_bandwidth=self.options.observer_bandwidth, kc_hat=self.kc_hat,
                   moving_samples=int(s[self._own(_OS_MOVING)]), breakaways=int(s[self._own(_OS_BREAKAWAYS)]))
        return out
