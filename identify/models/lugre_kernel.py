"""numba kernels for the LuGre friction model with the exact bristle update.

LuGre (paper eqs. 7-9; modelling notes 1)::

    tau_F = s0*z + s1*zdot + nu*qd,    zdot = qd - s0*|qd|*z/g(qd)

The bristle ODE is stiff (time constant g/(s0*|qd|), a fraction of a millisecond at speed),
so explicit Euler diverges at robot sampling rates for realistic s0. With qd held over a
sample interval the ODE is linear in z and its exact solution is (modelling notes 2)::

    z[k+1] = zss + (z[k] - zss)*exp(-s0*|qd[k]|*dt[k]/g[k]),   zss = g[k]*sgn(qd[k])/s0

which is stable for every s0 and step. The friction at sample k is the model evaluated
with the state at that sample: ``tau_F[k] = s0*z[k] + s1*zdot[k] + nu*qd[k]``.
The initial state is the steady state of the first velocity (zero at rest).

One step function (:func:`_advance`) serves simulation, prediction and the whole-population
fitness of the genetic algorithm, so fitting and prediction share one code path.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(inline="always", fastmath=True)
def _advance(z, v, dt, g, s0):
    """Exact bristle update over one interval with velocity ``v`` held."""
    a = abs(v)
    if a == 0.0:
        return z
    zss = g / s0 if v > 0.0 else -g / s0
    return zss + (z - zss) * math.exp(-s0 * a * dt / g)


@njit(inline="always", fastmath=True)
def _initial_state(v, g, s0):
    if v > 0.0:
        return g / s0
    if v < 0.0:
        return -g / s0
    return 0.0


@njit(inline="always", fastmath=True)
def stribeck_level_scalar(v, fc, fs, vs, delta):
    """Static level g(v) = fc + (fs - fc)*exp(-|v/vs|^delta) [Nm] (paper eq. 5)."""
    x = abs(v) / vs
    if x == 0.0:
        return fs
    return fc + (fs - fc) * math.exp(-math.exp(delta * math.log(x)))


@njit(cache=True, fastmath=True)
def lugre_stribeck(qd, dt, s0, s1, nu, fc, fs, vs, delta, z_out):
    """LuGre friction with the Stribeck static curve, fused in one pass.

    Parameters
    ----------
    qd : ndarray
        Velocity [rad/s] per sample.
    dt : ndarray
        Interval to the next sample [s] per sample.
    s0 [Nm/rad], s1 [Nm s/rad], nu [Nm s/rad], fc [Nm], fs [Nm], vs [rad/s], delta [-]
        LuGre and Stribeck parameters.
    z_out : ndarray
        Filled with the bristle state z [rad] at each sample.

    Returns
    -------
    ndarray
        Friction torque [Nm] per sample.
    """
    n = qd.size
    out = np.empty(n)
    g = stribeck_level_scalar(qd[0], fc, fs, vs, delta)
    z = _initial_state(qd[0], g, s0)
    for k in range(n):
        v = qd[k]
        g = stribeck_level_scalar(v, fc, fs, vs, delta)
        z_out[k] = z
        out[k] = s0 * z + s1 * (v - s0 * abs(v) * z / g) + nu * v
        z = _advance(z, v, dt[k], g, s0)
    return out


@njit(cache=True, fastmath=True)
def bristle_states(qd, dt, g, s0):
    """Bristle state z [rad] per sample for any static curve given as levels ``g`` [Nm]."""
    n = qd.size
    zs = np.empty(n)
    z = _initial_state(qd[0], g[0], s0)
    for k in range(n):
        zs[k] = z
        z = _advance(z, qd[k], dt[k], g[k], s0)
    return zs


def lugre_from_levels(qd, dt, g, s0, s1, nu):
    """LuGre friction [Nm] for static levels ``g`` [Nm] per sample (any static curve)."""
    z = bristle_states(qd, dt, g, s0)
    return s0 * z + s1 * (qd - s0 * np.abs(qd) * z / g) + nu * qd, z


@njit(inline="always")
def _solve_small(A, b, free, m):
    """Solve A[free][:,free] x = b[free] by Gaussian elimination; x is zero off ``free``."""
    idx = np.empty(m, dtype=np.int64)
    k = 0
    for i in range(m):
        if free[i]:
            idx[k] = i
            k += 1
    M = np.zeros((k, k + 1))
    for i in range(k):
        for j in range(k):
            M[i, j] = A[idx[i], idx[j]]
        M[i, k] = b[idx[i]]
        M[i, i] += 1e-12 * (abs(A[idx[i], idx[i]]) + 1e-300)
    ok = True
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if M[p, c] == 0.0:
            ok = False
            break
        if p != c:
            for j in range(k + 1):
                tmp = M[c, j]
                M[c, j] = M[p, j]
                M[p, j] = tmp
        for r in range(c + 1, k):
            f = M[r, c] / M[c, c]
            for j in range(c, k + 1):
                M[r, j] -= f * M[c, j]
    x = np.zeros(m)
    if not ok:
        return x, False
    sol = np.zeros(k)
    for i in range(k - 1, -1, -1):
        s = M[i, k]
        for j in range(i + 1, k):
            s -= M[i, j] * sol[j]
        sol[i] = s / M[i, i]
    for i in range(k):
        x[idx[i]] = sol[i]
    return x, True


@njit(inline="always")
def bounded_normal_solve(A, b, yy, nonneg, m):
    """Least squares from normal equations with sign constraints, exactly.

    Minimises ||y - X x||^2 given A = X^T X, b = X^T y, yy = y^T y, subject to x[i] >= 0
    where ``nonneg[i]``. With at most a few constrained variables every active set is
    tried; the best feasible one is the constrained optimum.

    Returns
    -------
    x : ndarray
    sse : float
    """
    best = np.zeros(m)
    best_sse = np.inf
    ncons = 0
    cons = np.empty(m, dtype=np.int64)
    for i in range(m):
        if nonneg[i]:
            cons[ncons] = i
            ncons += 1
    free = np.ones(m, dtype=np.bool_)
    for mask in range(1 << ncons):
        for i in range(m):
            free[i] = True
        for c in range(ncons):
            if (mask >> c) & 1:
                free[cons[c]] = False
        x, ok = _solve_small(A, b, free, m)
        if not ok:
            continue
        feasible = True
        for c in range(ncons):
            if x[cons[c]] < 0.0:
                feasible = False
        if not feasible:
            continue
        sse = yy
        for i in range(m):
            sse -= 2.0 * x[i] * b[i]
            for j in range(m):
                sse += x[i] * A[i, j] * x[j]
        if sse < best_sse:
            best_sse = sse
            best[:] = x
    return best, best_sse


@njit(parallel=True, cache=True, fastmath=True)
def population_sse(genes, qd, qdd, dt, y, rigid):
    """Fitness of a whole GA population in one parallel call (variable projection).

    Each individual fixes the nonlinear parameters ``genes[i] = (log10 s0, fc, fs - fc,
    log10 vs, delta)``; the parameters that enter linearly -- s1, nu and, when ``rigid``,
    the inertia J and offset c -- are then solved exactly by bounded least squares
    (s1, nu, J >= 0). ``y`` is the friction target (tau, or tau - tau_rb).

    Returns
    -------
    sse : ndarray (n_pop,)
        Sum of squared residuals [Nm^2].
    lin : ndarray (n_pop, 4)
        (s1, nu, J, c) of each individual.
    """
    n_pop = genes.shape[0]
    n = qd.size
    m = 4 if rigid else 2
    sse = np.empty(n_pop)
    lin = np.zeros((n_pop, 4))
    nonneg = np.zeros(m, dtype=np.bool_)
    nonneg[0] = True
    nonneg[1] = True
    if rigid:
        nonneg[2] = True
    for p in prange(n_pop):
        s0 = 10.0 ** genes[p, 0]
        fc = genes[p, 1]
        fs = fc + genes[p, 2]
        vs = 10.0 ** genes[p, 3]
        delta = genes[p, 4]
        A = np.zeros((m, m))
        b = np.zeros(m)
        xk = np.zeros(m)
        yy = 0.0
        g = stribeck_level_scalar(qd[0], fc, fs, vs, delta)
        z = _initial_state(qd[0], g, s0)
        for k in range(n):
            v = qd[k]
            g = stribeck_level_scalar(v, fc, fs, vs, delta)
            r = y[k] - s0 * z
            xk[0] = v - s0 * abs(v) * z / g
            xk[1] = v
            if rigid:
                xk[2] = qdd[k]
                xk[3] = 1.0
            for i in range(m):
                b[i] += xk[i] * r
                for j in range(i, m):
                    A[i, j] += xk[i] * xk[j]
            yy += r * r
            z = _advance(z, v, dt[k], g, s0)
        for i in range(m):
            for j in range(i):
                A[i, j] = A[j, i]
        x, s = bounded_normal_solve(A, b, yy, nonneg, m)
        sse[p] = s
        for i in range(m):
            lin[p, i] = x[i]
    return sse, lin
