"""A grid posterior over the friction (k_c, k_s) from the pulse-response likelihood.

solnic-modern's option ``friction_grid``. The linearised friction filters (the text's (5-15)–
(5-18) and the joint EKF) see one pulse size at a time through its quasipartials; from the
section-7.3 start (k̂ at half their values) they can run along the k_s/k_c ridge of Δc — many
(k_c, k_s) give the same motion for one Δt_u — and stay there (quiet-friction seed 2: k̂s ≈ 3.8
against a true 2.2). Here the posterior density of k = (k_c, k_s) [ozf·in] is kept on a
lattice of points and every pulse multiplies it by its exact likelihood:

    p(k | data) ∝ p0(k) · Π_j N(m_j; sign_j·D_j(k), R_j + v_j(k))            (1)

* p0 is the prior N(k̂(0), P_b(0)) restricted to the valid set 0 < k_c ≤ k_s < u_max: the
  constraints act on the distribution (points outside have zero mass), never by clipping.
* D_j(k) is the noise-free motion of pulse j with friction k, the plant's own closed form
  (:func:`plant.pulse_response`, compiled), plus the friction-noise bias b_j when the shaft
  moves; D_j(k) = 0 where k_s ≥ the pulse's peak torque (no breakaway).
* (m_j, R_j) is the samples' own evidence about the pulse's motion d: the posterior of d in
  the mode-2/joint filter with its prior divided out
  (:meth:`controllers.solnic.joint_filter.JointFilter.motion_likelihood`), so the
  prediction is not used twice.
* v_j(k) = v_w2 (the friction-noise variance of :mod:`controllers.solnic.noise_model`, where
  the shaft moves) + the spread of D_j over the lattice cell, |∇D|²h²/12 per lattice axis:
  the likelihood averaged over the cell that the point stands for, to first order. Without it
  a cell whose centre misses a sharp ridge of (1) would get no mass although part of the cell
  lies on it.

"No motion" needs no special case: where the samples say d ≈ 0, (1) favours the points with
k_s ≥ the peak torque (D = 0), i.e. it is censored evidence k_s ≥ peak torque, weighted by how
well the samples could have seen the predicted motion. An "undecided" cycle is the same
likelihood with a wide R.

The lattice is affine, k = c + A·(u, v) with (u, v) on a regular n × n grid of cell centres in
[−1, 1]². It starts as the box [0, hi]² (hi = max k̂(0) + 6σ, at most u_max) and is re-fitted
("zoom") to the posterior — centre at its mean, axes along the eigenvectors of its covariance,
half-widths ``width_sigmas``·σ — when the fitted box would have less than a quarter of the
current box's area or the mass on the edge cells exceeds 1e-4; all stored pulses are then
re-evaluated on the new lattice, so (1) stays exact up to the lattice. x5's drift while moving
(σ5² over ~3 ms per pulse, 5e-4 ozf²·in² in a 100 s run) is neglected.

The friction-noise moments at each lattice point scale with f = α²σ2²T_m³/3 (T_m that
point's moving time): variance r_v·f and bias r_b·√f, the ratios r_v, r_b taken from
:func:`controllers.solnic.noise_model.pulse_noise` at the point estimate (an approximation;
exact when σ2 = 0).

Limitation: each pulse's evidence (m_j, R_j) leans on the same drift estimate x̂4, so the
evidence of successive pulses is correlated while (1) multiplies it as independent. Over a
whole run the posterior grows confident in a Δc that is slightly off and x̂4 absorbs the
difference (quiet-friction NEES of (x̂1, x̂4) in the hundreds). solnic-modern therefore uses
the grid for the start-up only and hands its moments to the joint EKF, which carries the
k–x4 correlation (``grid_handover_sets``, :mod:`controllers.solnic.modern`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from plant.params import PlantParams
from controllers.models.acker import closed_form_kernel

__all__ = ["FrictionGrid", "Predictive", "pulse_table"]


@njit(cache=True)
def _table_kernel(dt_u, U, t3, a, kc, ks, need, dc, t_stop, t_brk):
    for i in range(kc.size):
        if not need[i]:
            dc[i], t_stop[i], t_brk[i] = 0.0, 0.0, -1.0
            continue
        d, tb, _, ts = closed_form_kernel(dt_u, U, t3, a, ks[i], kc[i])
        if tb < 0.0:
            dc[i], t_stop[i], t_brk[i] = 0.0, 0.0, -1.0
        else:
            dc[i], t_stop[i], t_brk[i] = d, ts, tb


@njit(cache=True)
def _valid_table_kernel(dt_u, U, t3, a, kc, ks, need, idx, n, ks_hi, dc, t_stop, t_brk, spread_out):
    """:meth:`FrictionGrid.table` in one call: the frictions clipped into the valid set,
    :func:`_table_kernel` on the needed points (``dc``, ``t_stop``, ``t_brk``: scratch of the
    n × n lattice), and at the valid points ``idx`` the cell spread² of Δc (into
    ``spread_out``) and (Δc, t_stop, t_breakaway) (returned).

    The same operations on the same operands as the numpy formulation it replaces, so the same
    bits: ``np.clip`` is min(max(x, lo), hi) elementwise; ``np.gradient`` with unit spacing is
    (f[i+1] − f[i−1])/2 inside and (f[1] − f[0])/1, (f[n−1] − f[n−2])/1 at the edges; the
    spread is 0 + |g0|·|g0|/12, then + |g1|·|g1|/12."""
    m = kc.size
    ks_c = np.empty(m)
    kc_c = np.empty(m)
    for i in range(m):
        k = max(ks[i], 1e-6)
        k = min(k, ks_hi)
        ks_c[i] = k
        c = max(kc[i], 1e-6)
        kc_c[i] = min(c, k)
    _table_kernel(dt_u, U, t3, a, kc_c, ks_c, need, dc, t_stop, t_brk)
    nv = idx.size
    dc_v, ts_v, tb_v = np.empty(nv), np.empty(nv), np.empty(nv)
    for j in range(nv):
        i = idx[j]
        r, c = i // n, i % n
        if r == 0:
            g0 = (dc[i + n] - dc[i]) / 1.0
        elif r == n - 1:
            g0 = (dc[i] - dc[i - n]) / 1.0
        else:
            g0 = (dc[i + n] - dc[i - n]) / 2.0
        if c == 0:
            g1 = (dc[i + 1] - dc[i]) / 1.0
        elif c == n - 1:
            g1 = (dc[i] - dc[i - 1]) / 1.0
        else:
            g1 = (dc[i + 1] - dc[i - 1]) / 2.0
        a0, a1 = abs(g0), abs(g1)
        sp = 0.0
        sp += a0 * a0 / 12.0
        sp += a1 * a1 / 12.0
        spread_out[j] = sp
        dc_v[j], ts_v[j], tb_v[j] = dc[i], t_stop[i], t_brk[i]
    return dc_v, ts_v, tb_v


def pulse_table(params: PlantParams, dt_u: float, kc: np.ndarray, ks: np.ndarray, need: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Δc [rad], t_stop [s], t_breakaway [s] or −1) of a +u_max pulse for every (k_c, k_s).

    The same closed form as the noise-free :func:`plant.pulse_response`, looped in compiled
    code; k_c must be > 0 (with k_c = 0 the shaft coasts for ever: Δc = nan). With ``need``
    (bool, one per point) only those points are evaluated; the others read (0, 0, −1).
    """
    kc = np.ascontiguousarray(kc, dtype=float)
    ks = np.ascontiguousarray(ks, dtype=float)
    need = np.ones(kc.shape, dtype=np.bool_) if need is None else np.ascontiguousarray(need, dtype=np.bool_)
    dc, ts, tb = np.empty_like(kc), np.empty_like(kc), np.empty_like(kc)
    _table_kernel(float(dt_u), params.u_max, params.motor_time_constant, params.alpha, kc, ks, need, dc, ts, tb)
    return dc, ts, tb


@dataclass(frozen=True)
class Predictive:
    """The posterior predictive of one +u_max pulse of Δt_u under the grid posterior.

    Attributes
    ----------
    p_motion : float
        Posterior probability that the pulse breaks the shaft away.
    dc_mean, dc_var : float
        Centre [rad] and spread² [rad²] of Δc given motion (nan without motion mass); see
        :meth:`FrictionGrid.predictive`.
    t_stop_mean, t_stop_var : float
        Stop time [s] and its variance [s²] (see :meth:`FrictionGrid.predictive`).
    """

    p_motion: float
    dc_mean: float
    dc_var: float
    t_stop_mean: float
    t_stop_var: float


class FrictionGrid:
    """Posterior of (k_c, k_s) on an adaptive affine lattice, equation (1) of the module.

    Parameters
    ----------
    params : PlantParams
        The nominal plant (α, τ3, u_max; its friction fields are not used).
    k0, P0 : array_like
        Prior mean (k_c, k_s) [ozf·in] and 2×2 covariance.
    n : int
        Points per lattice axis.
    width_sigmas : float
        Half-width of a re-fitted lattice in posterior standard deviations.
    memory : float
        Evidence of the pulse j steps back is weighted e^(−j/memory) (exponential forgetting
        of the log-likelihood; inf, the default, keeps all of it). See the module docstring.
    """

    def __init__(self, params: PlantParams, k0, P0, n: int = 64, width_sigmas: float = 6.0,
                 memory: float = math.inf) -> None:
        self.params = params
        self.u_max = float(params.u_max)
        self.k0 = np.asarray(k0, dtype=float).reshape(2)
        self.P0 = np.asarray(P0, dtype=float).reshape(2, 2)
        self.P0inv = _inv2(self.P0)
        self.n = int(n)
        if self.n < 2:      # the cell spread is a difference between neighbouring lattice points
            raise ValueError(f"n must be an integer >= 2 lattice points per axis, got {n!r}")
        self.width_sigmas = float(width_sigmas)
        if not memory > 0:
            raise ValueError(f"memory must be > 0 pulses, got {memory!r}")
        self.forget = math.exp(-1.0 / memory)       # weight of the evidence one pulse older
        self.obs: list[tuple[float, int, float, float, float, float]] = []
        sd = np.sqrt(np.diag(self.P0))
        hi = min(self.u_max, float(np.max(self.k0 + 6.0 * sd)))
        self.n_regrids = 0
        self._set_lattice(np.array([hi / 2, hi / 2]), np.diag([hi / 2, hi / 2]))

    # -- lattice --------------------------------------------------------------------------
    def _set_lattice(self, centre: np.ndarray, axes: np.ndarray) -> None:
        n = self.n
        g = (np.arange(n) + 0.5) / n * 2.0 - 1.0                  # cell centres in [−1, 1]
        U, V = np.meshgrid(g, g, indexing="ij")
        self.centre, self.axes = np.asarray(centre, float), np.asarray(axes, float)
        u, v, a = U.ravel(), V.ravel(), self.axes
        pts = np.vstack([self.centre[0] + (a[0, 0] * u + a[0, 1] * v),
                         self.centre[1] + (a[1, 0] * u + a[1, 1] * v)])      # c + A·(u, v)
        self.kc, self.ks = pts[0], pts[1]
        self.valid = (self.kc > 0) & (self.kc <= self.ks) & (self.ks < self.u_max)
        # the points a valid point's Δc and cell spread read: itself and its lattice neighbours
        # (np.gradient's central and one-sided differences)
        v = self.valid.reshape(n, n)
        need = v.copy()
        need[1:] |= v[:-1]
        need[:-1] |= v[1:]
        need[:, 1:] |= v[:, :-1]
        need[:, :-1] |= v[:, 1:]
        self._need = need.ravel()
        self._idx = np.flatnonzero(self.valid)
        e = pts[:, self._idx] - self.k0[:, None]
        q = self.P0inv
        self._log_prior = -0.5 * ((q[0, 0] * e[0] * e[0] + q[0, 1] * e[0] * e[1])
                                  + (q[1, 0] * e[1] * e[0] + q[1, 1] * e[1] * e[1]))     # e'·P0⁻¹·e
        self._tables: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        self._moving: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._kc_valid, self._ks_valid = self.kc[self._idx], self.ks[self._idx]
        self.version = getattr(self, "version", 0) + 1
        logL = np.zeros_like(self._log_prior)
        for ob in self.obs:
            logL = self.forget * logL + self._loglik(*ob)
        self._set_weights(logL)

    def _set_weights(self, logL: np.ndarray) -> None:
        self._logL = logL
        logw = self._log_prior + logL
        w = _exp_each(logw - np.max(logw))
        self.w = w / np.sum(w)
        kc, ks = self._kc_valid, self._ks_valid
        w = self.w
        self._mean = np.array([np.sum(w * kc), np.sum(w * ks)])
        d0, d1 = kc - self._mean[0], ks - self._mean[1]
        # a cell is the parallelogram of edges axes·(2/n): uniform within it, COV = Σ e e'/12
        c = self.axes * (2.0 / self.n)
        c00, c01, c11 = c[0, 0] * c[0, 0] + c[0, 1] * c[0, 1], c[0, 0] * c[1, 0] + c[0, 1] * c[1, 1], \
            c[1, 0] * c[1, 0] + c[1, 1] * c[1, 1]
        s01 = np.sum(w * d0 * d1) + c01 / 12.0
        self._cov = np.array([[np.sum(w * d0 * d0) + c00 / 12.0, s01], [s01, np.sum(w * d1 * d1) + c11 / 12.0]])

    def table(self, dt_u: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Δc, t_stop, t_breakaway, spread² of Δc over the cell) at the valid points."""
        key = float(dt_u)
        hit = self._tables.get(key)
        if hit is None:
            # compiled (:func:`_valid_table_kernel`): the numpy formulation (np.clip, pulse_table,
            # np.gradient's cell spread; tests/reference_kernels.grid_table), bit for bit
            p, nn = self.params, self.n * self.n
            spread = np.empty(self._idx.size)
            dc, ts, tb = _valid_table_kernel(key, p.u_max, p.motor_time_constant, p.alpha, self.kc, self.ks,
                                             self._need, self._idx, self.n, self.u_max * (1 - 1e-9),
                                             np.empty(nn), np.empty(nn), np.empty(nn), spread)
            hit = (dc, ts, tb, spread)
            if len(self._tables) > 64:
                self._tables.clear()
                self._moving.clear()
            self._tables[key] = hit
        return hit

    # -- the posterior -------------------------------------------------------------------
    @property
    def mean(self) -> np.ndarray:
        """Posterior mean (k_c, k_s) [ozf·in]."""
        return self._mean.copy()

    @property
    def cov(self) -> np.ndarray:
        """Posterior covariance, including the spread within a cell [ozf²·in²]."""
        return self._cov.copy()

    def points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k_c, k_s, weight) of the valid lattice points."""
        return self.kc[self._idx].copy(), self.ks[self._idx].copy(), self.w.copy()

    def noise_moments(self, dt_u: float, var_ratio: float, bias_ratio: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Δc + bias, VAR from w2 + cell spread, moves, t_stop) at the valid points.

        The friction-noise moments scale with f = α²σ2²T_m³/3 (T_m the moving time at the
        point): variance ``var_ratio``·f and bias ``bias_ratio``·√f, the ratios taken from
        :func:`controllers.solnic.noise_model.pulse_noise` at the point estimate.
        """
        dc, ts, tb, spread = self.table(dt_u)
        moves, f, root_f = self._moving_time(float(dt_u), ts, tb)
        if f is not None and (var_ratio > 0 or bias_ratio > 0):
            return dc + bias_ratio * root_f, spread + var_ratio * f, moves, ts
        return dc, spread, moves, ts

    def _moving_time(self, key: float, ts: np.ndarray, tb: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(moves, f = α²σ2²T_m³/3, √f) of the table ``key`` at the valid points (f None
        without friction noise), kept with the table: they depend on nothing else. Read-only."""
        hit = self._moving.get(key)
        if hit is None:
            moves = tb >= 0.0
            s2 = self.params.alpha**2 * self.params.sigma2_sq
            f = root_f = None
            if s2 > 0:
                tm = np.maximum(ts - tb, 0.0)
                # T_m³ as T_m·T_m·T_m (two correctly rounded products), not ** 3: numpy's power
                # ufunc has an AVX-512 loop that rounds otherwise than libm's pow (measured)
                f = np.where(moves, s2 * (tm * tm * tm) / 3.0, 0.0)
                root_f = np.sqrt(f)
                f.flags.writeable = root_f.flags.writeable = False
            moves.flags.writeable = False
            hit = self._moving[key] = (moves, f, root_f)
        return hit

    def _loglik(self, dt_u: float, sign: int, m: float, R: float, var_ratio: float,
                bias_ratio: float) -> np.ndarray:
        # −(m − d)²/(2(R + v)) compiled (:func:`_loglik_kernel`, the numpy expression's operations
        # on the same operands), log(R + v) by libm's log element by element (:func:`_log_each`)
        dc, ts, tb, spread = self.table(dt_u)
        moves, f, root_f = self._moving_time(float(dt_u), ts, tb)
        noisy = f is not None and (var_ratio > 0 or bias_ratio > 0)
        var, quad = np.empty(dc.size), np.empty(dc.size)
        _loglik_kernel(dc, spread, moves, root_f if noisy else dc, f if noisy else dc, noisy, float(var_ratio),
                       float(bias_ratio), float(sign), float(m), float(R), var, quad)
        return quad - 0.5 * _log_each(var)

    def update(self, dt_u: float, sign: int, m: float, R: float, var_ratio: float = 0.0,
               bias_ratio: float = 0.0) -> None:
        """Multiply by the likelihood of one pulse: evidence d ~ N(m, R) [rad, rad²] about its
        signed motion; ``var_ratio``/``bias_ratio`` scale the friction-noise moments
        (:meth:`noise_moments`)."""
        if not (math.isfinite(m) and R > 0 and math.isfinite(R)):
            return
        ob = (float(dt_u), int(sign), float(m), float(R), float(var_ratio), float(bias_ratio))
        self.obs.append(ob)
        self._set_weights(self.forget * self._logL + self._loglik(*ob))
        self._maybe_regrid()

    def _edge_mass(self) -> float:
        n = self.n
        full = np.zeros(n * n)
        full[self._idx] = self.w
        full = full.reshape(n, n)
        return float(full[0].sum() + full[-1].sum() + full[1:-1, 0].sum() + full[1:-1, -1].sum())

    def _maybe_regrid(self) -> None:
        lam, vec = _eigh2(self._cov)
        lam = np.maximum(lam, 1e-10)
        new_axes = vec * (self.width_sigmas * np.sqrt(lam))
        area_new = abs(_det2(new_axes))
        area_now = abs(_det2(self.axes))
        edge = self._edge_mass()
        if area_new < 0.25 * area_now or edge > 1e-4:
            if not area_new < 0.25 * area_now:
                # mass on the edge: re-centre, and do not shrink below half the current box
                half = 0.5 * np.sqrt(np.sum(self.axes * self.axes, axis=0)).min()
                new_axes = vec * np.maximum(self.width_sigmas * np.sqrt(lam), half)
            self.n_regrids += 1
            self._set_lattice(self._mean, new_axes)

    def predictive(self, dt_u: float, var_ratio: float = 0.0, bias_ratio: float = 0.0) -> Predictive:
        """The posterior predictive of a +u_max pulse of ``dt_u`` given that it moves the shaft.

        Robust statistics: the posterior puts small mass on far points (k_c → 0 coasts for a
        long way) whose Δc would dominate a mean, so ``dc_mean`` is the weighted median of
        E[Δc | k] (friction-noise bias included, :meth:`noise_moments`), ``dc_var`` the square
        of half the 16–84 % range plus the friction-noise variance at the median; likewise the stop
        time's median and spread² (t_max = median + 3·spread, (5-11)). A far quantile of the
        stop time (0.9987) would wait for those far points: on quiet-friction seed 3 it kept
        the mode-2 filter blind for 1.8 s after every start-up pulse (peak 864 µrad).
        """
        mean, var, moves, ts = self.noise_moments(dt_u, var_ratio, bias_ratio)
        w = self.w * moves
        p = float(np.sum(w))
        if not p > 0:
            return Predictive(0.0, math.nan, math.nan, math.nan, math.nan)
        # the points of weight > 1e-9·p (negligible points cannot move a quantile much), their
        # weights / p, the weighted 16/50/84 % quantiles of Δc and t_stop and the friction-noise
        # variance at the median point: :func:`_predictive_kernel` (:func:`_weighted_quantiles`'
        # operations, compiled)
        q16, q50, q84, var50, t16, t50, t84 = _predictive_kernel(w, p, mean, var, ts)
        return Predictive(p, q50, (0.5 * (q84 - q16)) ** 2 + var50, t50, (0.5 * (t84 - t16)) ** 2)


def _inv2(m: np.ndarray) -> np.ndarray:
    """The inverse of a 2 × 2 matrix, [[d, −b], [−c, a]]/(a·d − b·c)."""
    det = _det2(m)
    if det == 0.0 or not math.isfinite(det):
        raise ValueError(f"the prior covariance must be invertible, got {m.tolist()!r}")
    return np.array([[m[1, 1] / det, -m[0, 1] / det], [-m[1, 0] / det, m[0, 0] / det]])


def _det2(m: np.ndarray) -> float:
    """a·d − b·c of a 2 × 2 matrix."""
    return float(m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0])


def _eigh2(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eigenvalues ascending, eigenvectors as columns) of a symmetric 2 × 2 matrix by one Jacobi
    rotation (Golub & Van Loan, Matrix Computations, 4th ed., Algorithm 8.5.1 sym.schur2): the
    rotation with tangent t = sign(τ)/(|τ| + √(1 + τ²)), τ = (c − a)/(2b), zeros b; plain float
    arithmetic, so the same bits on every machine (LAPACK's would follow the BLAS kernel)."""
    a, b, c = float(m[0, 0]), float(0.5 * (m[0, 1] + m[1, 0])), float(m[1, 1])
    if b == 0.0:
        cs, sn, l0, l1 = 1.0, 0.0, a, c
    else:
        tau = (c - a) / (2.0 * b)
        t = (1.0 if tau >= 0 else -1.0) / (abs(tau) + math.sqrt(1.0 + tau * tau))
        cs = 1.0 / math.sqrt(1.0 + t * t)
        sn = t * cs
        l0, l1 = a - t * b, c + t * b
    vec = np.array([[cs, sn], [-sn, cs]])              # columns: the eigenvectors of l0, l1
    if l1 < l0:
        return np.array([l1, l0]), vec[:, ::-1].copy()
    return np.array([l0, l1]), vec


@njit(cache=True)
def _exp_each(x):
    """exp of each entry by libm (``math.exp`` compiled: one scalar call per entry), not numpy's
    ufunc, whose SIMD loop numpy picks by CPU (AVX-512 and AVX2 round differently: measured,
    docs/results.md, "Reproducibility across machines")."""
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = math.exp(x[i])
    return out


@njit(cache=True)
def _log_each(x):
    """log of each entry by libm (``math.log`` compiled), as :func:`_exp_each`; x > 0 here (R + v)."""
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = math.log(x[i])
    return out


@njit(cache=True)
def _loglik_kernel(dc, spread, moves, root_f, f, noisy, var_ratio, bias_ratio, sign, m, R, var, quad):
    """R + v and −½(m − d)²/(R + v) of :meth:`FrictionGrid._loglik` at every valid point, into
    ``var`` and ``quad``: (Δc + b·√f, spread + r·f) (:meth:`FrictionGrid.noise_moments`; Δc,
    spread without the ratios), d = sign·mean where the shaft moves, else 0 — the numpy
    expression's operations in its order ((m − d)² as (m − d)·(m − d), numpy's square)."""
    for i in range(dc.size):
        if noisy:
            mean = dc[i] + bias_ratio * root_f[i]
            v = spread[i] + var_ratio * f[i]
        else:
            mean = dc[i]
            v = spread[i]
        d = sign * mean if moves[i] else 0.0
        v = R + v
        e = m - d
        var[i] = v
        quad[i] = -0.5 * (e * e) / v


@njit(cache=True)
def _predictive_kernel(w, p, mean, var, ts):
    """(Δc's 16/50/84 % quantiles, VAR at the Δc median's point, t_stop's quantiles) of
    :meth:`FrictionGrid.predictive` from the weights ``w`` (sum ``p`` > 0): the points with
    w > 1e-9·p, weights w/p, and :func:`_weighted_quantiles` of each — a stable argsort
    (mergesort), the running sum, the left-side search of q·(total) clipped to the last index:
    the same operations on the same operands as the numpy code, so the same bits."""
    keep = np.flatnonzero(w > 1e-9 * p)
    m = keep.size
    wk, mk, tk = np.empty(m), np.empty(m), np.empty(m)
    for j in range(m):
        i = keep[j]
        wk[j], mk[j], tk[j] = w[i] / p, mean[i], ts[i]
    qm, om = _quantiles3(mk, wk)
    qt, _ = _quantiles3(tk, wk)
    return qm[0], qm[1], qm[2], var[keep[om]], qt[0], qt[1], qt[2]


@njit(cache=True)
def _quantiles3(x, w):
    """The 0.16, 0.5 and 0.84 quantiles of Σ w_i δ(x_i) and the index of the 0.5 one's point,
    as :func:`_weighted_quantiles` computes them."""
    order = np.argsort(x, kind="mergesort")
    n = x.size
    cw = np.empty(n)
    acc = 0.0
    for j in range(n):
        acc += w[order[j]]
        cw[j] = acc
    total = cw[n - 1]
    q = np.empty(3)
    mid = 0
    for k, frac in enumerate((0.16, 0.5, 0.84)):
        i = min(np.searchsorted(cw, frac * total), n - 1)
        q[k] = x[order[i]]
        if k == 1:
            mid = order[i]
    return q, mid


def _weighted_quantiles(x: np.ndarray, w: np.ndarray, qs) -> tuple[list[float], int]:
    """Quantiles of Σ w_i δ(x_i) (w sums to ≤ 1; lower convention), and the index of the
    point at the middle requested quantile."""
    order = np.argsort(x, kind="stable")
    cw = np.cumsum(w[order])
    idx = np.minimum(np.searchsorted(cw, np.asarray(qs) * cw[-1]), len(x) - 1)
    return [float(v) for v in x[order][idx]], int(order[idx[len(idx) // 2]])
