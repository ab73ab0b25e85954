"""Two-mass drive model per joint: motor, elastic gear with backlash, link, friction, cascaded control.

Per joint ``j`` (joint-side units throughout: motor angle and torque divided / multiplied by the
gear ratio ``N``; equations and sources in ``docs/drive-model.md``)::

    J_m' theta_dd = u - tau_fm - tau_s                   motor side, J_m' = N^2 J_m
    J_l  q_dd     = tau_s - tau_load - tau_fl            link side, J_l = M_jj(q)
    tau_s = elasto-backlash(delta = theta - q, delta_d)  gear torque

* **Gear** (Modelica ``Rotational.Components.ElastoBacklash``): no torque while
  ``|delta| <= b/2``; outside ``c (delta -+ b/2) + d delta_d``, and the damping may not pull
  (the torque keeps the sign of the contact flank). ``b = 0`` gives a linear spring-damper.
  The play is therefore crossed where the *transmitted torque* changes sign, not where the
  velocity does: a joint held on one flank by gravity stays there through a velocity reversal.
* **Load** ``tau_load``: gravity, inertial coupling of the other joints and the process force
  through ``J^T``, supplied by the caller per cycle (linear within it);
  :func:`load_torques` computes it with the Newton-Euler model of :mod:`simulate.robot.dynamics`.
* **Friction** acts on the motor or the link side (``DriveParams.side``): one call per joint and
  substep of the loop-friction dispatch :func:`simulate.robot.loop_friction.friction_torque` (any
  fitted model type, or the robot file's inline LuGre as a LoopFriction of kind LUGRE), on the
  simulated velocity and position of that side, with the gear torque as the gearbox load.
* **Control** as an NC drive, evaluated every substep: position P from the motor encoder,
  velocity PI on the motor speed, velocity and torque feed-forward::

      theta_r = r + [WINDUP] (tau_g - (d/c) d/dt tau_g + [FF_FRICTION, joint side] f_ff) / c
      v_cmd   = kv (theta_r - theta) + ff_vel * d/dt theta_r
      u       = kp (v_cmd - omega) + ki int(v_cmd - omega) dt
                + ff_tau ((J_m' + J_l) r_dd + tau_model) + [FF_FRICTION] f_ff

  with ``tau_g = ff_tau (J_l r_dd + tau_model)`` the torque the NC's model expects through the
  gear and ``tau_model`` the load the NC knows (gravity and inertia; not the process force);
  ``f_ff`` the friction the NC's model predicts along the command, each joint's model run with its
  own dynamics (:func:`simulate.robot.loop_friction.command_friction`; linear within a cycle).
  The reference ``r`` is the cubic Hermite interpolant of the commanded link positions and
  velocities at the cycle ends; the acceleration ``r_dd`` of the feed-forward is linear between
  the commanded accelerations at the cycle ends (the Hermite's own jerk would triple the error of
  difference velocities); the feed-forward torque is evaluated at substep midpoints.

Integration (the gear is stiff: ``f_r = sqrt(c (1/J_m' + 1/J_l)) / 2 pi`` is 25-200 Hz): each
cycle ``T`` is cut, per joint, into ``n_sub[j]`` substeps of ``h = T / n_sub[j]`` (the joints are
independent within a cycle, their load being given, so each runs at its own rate). The control
torque is held over a substep (zero-order hold, as a digital current loop), friction (the model's
own discretisation) is evaluated at the substep's start and held, and the two masses are advanced
by velocity Verlet (kick-drift-kick; second order, symplectic: no numerical damping of the gear
mode, stable for ``omega h < 2``). :func:`substeps_for` picks ``n_sub[j]`` so that
``omega_max h <= OMEGA_H = 0.2`` where ``omega_max`` bounds joint j's gear mode, bristle mode
``sqrt(s0 / J_side)``, damping rates and velocity-loop rate ``kp / J_m'``: the phase error of the
gear mode is then below ``(omega h)^2 / 24 = 0.17 %`` per period and the discrete velocity loop's
pole ``1 - kp h / J_m'`` is at 0.8 (stable below 2). At a 2 ms cycle the shipped robot needs 18,
18, 14, 5, 5, 13 substeps (A1, A2: the velocity loop, ``kp / J_m' = 1780 1/s``; A6: its gear mode
at 200 Hz), 73 joint-substeps per cycle. With ``OMEGA_H = 0.1`` (143) the circle test's spikes
and lost motions differ by less than 0.1 µm and every closed-form test passes with either.
"""
from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import numpy as np
from numba import njit

from identify.errors import InputError
from simulate.robot.dynamics import _rnea_kernel
from simulate.robot.loop_friction import bristle_rates, friction_torque

N_AXES = 6
CYCLE = 0.002   # s, interpolation cycle

#: Bound on omega * h that :func:`substeps_for` enforces [-] (module docstring: why 0.2).
OMEGA_H = 0.2


class DriveFlags(IntFlag):
    """Switches of the drive model (one int for the kernel)."""

    NONE = 0
    FRICTION = 1       #: friction torque on
    BACKLASH = 2       #: gear play on (off: b = 0, a linear spring-damper)
    FF_VEL = 4         #: velocity feed-forward (factor ``ff_vel`` per joint)
    FF_TAU = 8         #: torque feed-forward (factor ``ff_tau`` per joint)
    FF_FRICTION = 16   #: friction feed-forward from the NC's friction model along the command (off by default)
    WINDUP = 32        #: gear windup compensation of the motor setpoint by the model torque

    @classmethod
    def default(cls) -> DriveFlags:
        """Friction and backlash on; velocity, torque feed-forward and windup compensation on."""
        return cls.FRICTION | cls.BACKLASH | cls.FF_VEL | cls.FF_TAU | cls.WINDUP


# the members as plain ints for the compiled kernels (numba does not type IntFlag arithmetic)
F_FRICTION = int(DriveFlags.FRICTION)
F_BACKLASH = int(DriveFlags.BACKLASH)
F_FF_VEL = int(DriveFlags.FF_VEL)
F_FF_TAU = int(DriveFlags.FF_TAU)
F_FF_FRICTION = int(DriveFlags.FF_FRICTION)
F_WINDUP = int(DriveFlags.WINDUP)


class Contact(IntEnum):
    """Gear flank state: which flank transmits (``delta = theta - q`` beyond +-b/2) or the gap."""

    NEGATIVE = -1
    GAP = 0
    POSITIVE = 1


class FrictionSide(IntEnum):
    """Where the friction torque acts."""

    JOINT = 0   #: on the link (gear output, joint bearings)
    MOTOR = 1   #: on the motor (rotor bearings, gear input), before the gear's elasticity


#: Per-joint parameters, arrays of shape (6,) [SI, joint side]:
#: jm reflected motor inertia N^2 J_m [kg m^2]; c gear stiffness [Nm/rad]; d gear damping [Nm s/rad];
#: b total play [rad]; kv [1/s], kp [Nm s/rad], ki [Nm/rad] loop gains; ffv, fft feed-forward factors [-];
#: side FrictionSide (int64); t1 [Nm], p1 [rad] the gear's soft zone (:func:`elastic_torque`: the
#: torque at which the catalogue quotes the lost motion and half that lost motion; 0, 0: none).
#: The friction itself is a separate LoopFriction (:mod:`simulate.robot.loop_friction`) with its state array.
DriveParams = namedtuple("DriveParams", "jm c d b kv kp ki ffv fft side t1 p1")

#: Per-joint state, arrays of shape (6,), updated in place by :func:`drive_step`:
#: theta motor position [rad], omega motor velocity [rad/s] (both joint side), q, qd link position [rad]
#: and velocity [rad/s], integ velocity-loop integrator [Nm], u motor torque [Nm], tau_s gear
#: torque [Nm], tau_f friction torque [Nm], contact Contact (int64). The friction model's own state
#: (bristles, hidden state) is the LoopFriction state array beside it.
DriveState = namedtuple("DriveState", "theta omega q qd integ u tau_s tau_f contact")

#: One cycle's input, arrays of shape (6,), values at the cycle start (0) and end (1):
#: r0, r1 commanded link positions [rad]; v0, v1 commanded velocities [rad/s]; a0, a1 commanded
#: accelerations [rad/s^2] (linear within the cycle, for the feed-forward); load0, load1 actual
#: load torque on the link [Nm]; model0, model1 load torque the NC's feed-forward knows [Nm];
#: jl link inertia M_jj(q) [kg m^2]; ff0, ff1 the friction the NC's model predicts along the command [Nm]
#: (:func:`simulate.robot.loop_friction.command_friction`; used with ``FF_FRICTION``).
CycleInput = namedtuple("CycleInput", "r0 r1 v0 v1 a0 a1 load0 load1 model0 model1 jl ff0 ff1")


# --------------------------------------------------------------------------- per-step kernels

@njit(cache=True)
def elastic_torque(c, t1, p1, phi):
    """Torque [Nm] of the gear's spring at twist ``phi`` [rad] beyond the play (the catalogue curve's midline).

    A soft zone of stiffness ``t1 / p1`` up to ``|phi| = p1`` (the torque ``t1``), then the torsional
    rigidity ``c``: ``sign(phi) (t1 + c (|phi| - p1))``. ``p1 = t1 = 0``: the linear spring ``c phi``.
    """
    a = abs(phi)
    e = t1 / p1 * a if (p1 > 0.0 and a <= p1) else t1 + c * (a - p1)
    return e if phi >= 0.0 else -e


@njit(cache=True)
def elastic_twist(c, t1, p1, tau):
    """Twist [rad] of the gear's spring (no play) under the static torque ``tau`` [Nm]: the inverse of
    :func:`elastic_torque`."""
    a = abs(tau)
    x = a * p1 / t1 if (t1 > 0.0 and a <= t1) else p1 + (a - t1) / c
    return x if tau >= 0.0 else -x


@njit(cache=True)
def local_stiffness(c, t1, p1, tau):
    """Slope [Nm/rad] of the gear's spring at the static torque ``tau`` [Nm]: ``t1 / p1`` in the soft zone,
    else ``c``."""
    return t1 / p1 if abs(tau) < t1 else c


@njit(cache=True)
def gear_torque_soft(c, d, b2, t1, p1, delta, delta_d):
    """Gear torque [Nm] at deflection ``delta`` [rad], rate ``delta_d`` [rad/s]: play ``+-b2`` [rad], then the
    spring of :func:`elastic_torque` (soft zone ``t1`` [Nm] over ``p1`` [rad], rigidity ``c``), damping ``d``.

    The play and the spring in series trace the catalogue's hysteresis loop: loading and unloading
    branches ``b = 2 b2`` apart at every torque (the hysteresis loss, the twist width at zero
    torque), the midline through ``+-p1`` at ``+-t1`` (the lost motion ``2 p1`` at the torque at
    which it is quoted) and of slope ``c`` beyond (the torsional rigidity). The damper may not pull
    the flanks together (the torque keeps the sign of the contact flank).
    """
    if b2 <= 0.0:
        return elastic_torque(c, t1, p1, delta) + d * delta_d
    if delta > b2:
        t = elastic_torque(c, t1, p1, delta - b2) + d * delta_d
        return t if t > 0.0 else 0.0
    if delta < -b2:
        t = elastic_torque(c, t1, p1, delta + b2) + d * delta_d
        return t if t < 0.0 else 0.0
    return 0.0


@njit(cache=True)
def gear_torque(c, d, b2, delta, delta_d):
    """Elasto-backlash gear torque [Nm] for deflection ``delta`` [rad], rate ``delta_d`` [rad/s], half play b2 [rad]
    (a linear spring beyond the play: :func:`gear_torque_soft` without a soft zone)."""
    return gear_torque_soft(c, d, b2, 0.0, 0.0, delta, delta_d)


@njit(cache=True)
def _contact(delta, b2):
    if delta > b2:
        return 1
    if delta < -b2:
        return -1
    return 0


@njit(cache=True)
def drive_init(p, st, fst, r, v, load, model, jl, flags):
    """Put ``st`` at rest-equilibrium (velocity ``v``) on the reference ``r`` [rad] under ``load`` [Nm].

    The motor sits on its (windup-compensated) setpoint, the gear carries ``load`` on the flank
    its sign selects (centred in the play at zero load), the integrator holds the torque the
    feed-forward does not supply; the friction state ``fst`` is reset (each model starts at its
    steady state on the first call: LuGre bristles relaxed at rest).
    """
    fst[:, :] = 0.0
    for j in range(N_AXES):
        b2 = 0.5 * p.b[j] if flags & F_BACKLASH else 0.0
        fft = p.fft[j] if flags & F_FF_TAU else 0.0
        tg = fft * model[j]
        sh = r[j] + (elastic_twist(p.c[j], p.t1[j], p.p1[j], tg) if flags & F_WINDUP else 0.0)
        sg = 1.0 if load[j] > 0 else (-1.0 if load[j] < 0 else 0.0)
        dl = elastic_twist(p.c[j], p.t1[j], p.p1[j], load[j]) + sg * b2
        st.theta[j] = sh
        st.q[j] = sh - dl
        st.omega[j] = v[j]
        st.qd[j] = v[j]
        st.integ[j] = load[j] - fft * model[j]
        st.u[j] = load[j]
        st.tau_s[j] = load[j]
        st.tau_f[j] = 0.0
        st.contact[j] = _contact(dl, b2) if b2 > 0.0 else (1 if dl > 0 else (-1 if dl < 0 else 0))


@njit(cache=True)
def drive_step(p, fp, st, fst, cy, T, n_sub, flags):
    """Advance the six drives by one cycle of ``T`` [s], joint j in ``n_sub[j]`` substeps; updates ``st`` in place.

    Parameters
    ----------
    p : DriveParams
    fp : simulate.robot.loop_friction.LoopFriction
        Each joint's friction model, evaluated once per substep at the substep's start on the side
        ``p.side`` says (velocity, position) with the gear torque as the gearbox load, and held
        over the substep.
    st : DriveState
        State at the cycle start; holds the state at the cycle end on return (``u``, ``tau_s``,
        ``tau_f`` are the last substep's values, ``contact`` the flank at the end).
    fst : ndarray (6, S)
        Friction state (:func:`simulate.robot.loop_friction.new_state`), updated in place.
    cy : CycleInput
        Reference, load and link inertia of this cycle.
    T : float
        Cycle time [s].
    n_sub : ndarray (6,) of int64
        Substeps per joint (see :func:`substeps_for`): the joints are independent within a cycle
        (the load is given), so each runs at the rate its own fastest mode needs.
    flags : int
        :class:`DriveFlags`.
    """
    fr_on = flags & F_FRICTION
    for j in range(N_AXES):
        ns = n_sub[j]
        h = T / ns
        b2 = 0.5 * p.b[j] if flags & F_BACKLASH else 0.0
        ffv = p.ffv[j] if flags & F_FF_VEL else 0.0
        fft = p.fft[j] if flags & F_FF_TAU else 0.0
        jm = p.jm[j]
        jl = cy.jl[j]
        c = p.c[j]
        d = p.d[j]
        t1 = p.t1[j]
        p1 = p.p1[j]
        side = p.side[j]
        theta, omega, q, qd = st.theta[j], st.omega[j], st.q[j], st.qd[j]
        integ = st.integ[j]
        u = st.u[j]
        ts = st.tau_s[j]
        tf = 0.0
        dmod = (cy.model1[j] - cy.model0[j]) / T
        # feed-forward acceleration linear in the cycle: the cubic Hermite's own jerk would amplify
        # the error of difference velocities (it is 3x the true jerk for central differences)
        jerk = (cy.a1[j] - cy.a0[j]) / T
        # cubic Hermite reference r(s) = h0 + h1 s + h2 s^2 + h3 s^3, s = (time in the cycle) / T
        h0, h1 = cy.r0[j], T * cy.v0[j]
        h2 = 3.0 * (cy.r1[j] - h0) - 2.0 * h1 - T * cy.v1[j]
        h3 = 2.0 * (h0 - cy.r1[j]) + h1 + T * cy.v1[j]
        for i in range(ns):
            sa = i / ns
            sm = (i + 0.5) / ns
            r = h0 + sa * (h1 + sa * (h2 + sa * h3))
            rd = (h1 + sa * (2.0 * h2 + 3.0 * sa * h3)) / T
            rdd = cy.a0[j] + jerk * sa * T
            rddm = cy.a0[j] + jerk * sm * T
            mod_a = cy.model0[j] + dmod * sa * T
            mod_m = cy.model0[j] + dmod * sm * T
            # NC: motor setpoint (windup compensated), position P, velocity PI, feed-forward
            th_r = r
            th_rd = rd
            if flags & F_WINDUP:
                # spring(delta) + d delta_d = tau_g to first order in d/k (k the local slope):
                # delta = twist(tau_g) - (d/k) tau_g_d / k
                tg_d = fft * (jl * jerk + dmod)
                tg = fft * (jl * rdd + mod_a)
                if flags & F_FF_FRICTION and side == 0:
                    # joint-side friction the NC expects also passes the gear: its windup too
                    # (position only: its derivative is steep at each reversal)
                    tg += cy.ff0[j] + (cy.ff1[j] - cy.ff0[j]) * sa
                kl = local_stiffness(c, t1, p1, tg)
                th_r += elastic_twist(c, t1, p1, tg) - d / kl * tg_d / kl
                th_rd += tg_d / kl
            vcmd = p.kv[j] * (th_r - theta) + ffv * th_rd
            ev = vcmd - omega
            integ += p.ki[j] * ev * h
            uff = fft * ((jm + jl) * rddm + mod_m)
            if flags & F_FF_FRICTION:
                uff += cy.ff0[j] + (cy.ff1[j] - cy.ff0[j]) * sm
            u = p.kp[j] * ev + integ + uff
            # friction on the simulated motion of its side now (gearbox load: the gear torque), held
            # over the substep
            tfm = 0.0
            tfl = 0.0
            if fr_on:
                if side == 1:
                    tf = friction_torque(fp, j, fst, omega, theta, ts, h)
                    tfm = tf
                else:
                    tf = friction_torque(fp, j, fst, qd, q, ts, h)
                    tfl = tf
            load = cy.load0[j] + (cy.load1[j] - cy.load0[j]) * sm
            # velocity Verlet: kick, drift, kick (gear torque at both ends of the substep)
            ts = gear_torque_soft(c, d, b2, t1, p1, theta - q, omega - qd)
            omega += 0.5 * h * (u - tfm - ts) / jm
            qd += 0.5 * h * (ts - load - tfl) / jl
            theta += h * omega
            q += h * qd
            ts = gear_torque_soft(c, d, b2, t1, p1, theta - q, omega - qd)
            omega += 0.5 * h * (u - tfm - ts) / jm
            qd += 0.5 * h * (ts - load - tfl) / jl
        st.theta[j] = theta
        st.omega[j] = omega
        st.q[j] = q
        st.qd[j] = qd
        st.integ[j] = integ
        st.u[j] = u
        st.tau_s[j] = ts
        st.tau_f[j] = tf
        dl = theta - q
        st.contact[j] = _contact(dl, b2) if b2 > 0.0 else (1 if ts > 0 else (-1 if ts < 0 else 0))


@njit(cache=True)
def _run_kernel(p, fp, st, fst, ref, load, model, jl, ff, t, n_sub, flags, out_f, out_c):
    """Run the drives along a whole command (``ff``: the NC's friction feed-forward per cycle [Nm]);
    out_f (6, M, 6): q, theta, tau_s, tau_f, u; out_c (M, 6)."""
    m = t.shape[0]
    r, v, a = ref[0], ref[1], ref[2]
    drive_init(p, st, fst, r[0], v[0], load[0], model[0], jl[0], flags)
    for k in range(m):
        if k > 0:
            cy = CycleInput(r[k - 1], r[k], v[k - 1], v[k], a[k - 1], a[k], load[k - 1], load[k], model[k - 1],
                            model[k], 0.5 * (jl[k - 1] + jl[k]), ff[k - 1], ff[k])
            drive_step(p, fp, st, fst, cy, t[k] - t[k - 1], n_sub, flags)
        for j in range(N_AXES):
            out_f[0, k, j] = st.q[j]
            out_f[1, k, j] = st.theta[j]
            out_f[2, k, j] = st.tau_s[j]
            out_f[3, k, j] = st.tau_f[j]
            out_f[4, k, j] = st.u[j]
            out_c[k, j] = st.contact[j]


# --------------------------------------------------------------------------- Python side

def nc_friction(fp, t, q, v, gear_load, flags: int) -> np.ndarray:
    """The NC's friction feed-forward [Nm] (N, 6) along the command ``q`` [rad], ``v`` [rad/s] at ``t`` [s]
    with ``FF_FRICTION`` in ``flags`` (:func:`simulate.robot.loop_friction.command_friction`), zeros
    without it. ``gear_load`` [Nm] (N, 6) is the torque the NC's model expects through the gear,
    ``J_l r_dd + tau_model`` (the gearbox load of a load-dependent friction model), the same the
    backlash compensation predicts with (:func:`simulate.robot.backlash.predicted_gear_torque`)."""
    from simulate.robot.loop_friction import command_friction

    if not int(flags) & F_FF_FRICTION:
        return np.zeros(np.shape(q))
    return np.ascontiguousarray(command_friction(fp, t, q, v, gear_load))


def new_state() -> DriveState:
    """A zeroed :class:`DriveState` (use :func:`drive_init` to put it at equilibrium)."""
    return DriveState._make([np.zeros(N_AXES) for _ in range(8)] + [np.zeros(N_AXES, dtype=np.int64)])


def substeps_for(p: DriveParams, jl, T: float = CYCLE, flags: int = int(DriveFlags.default()),
                 friction=None) -> np.ndarray:
    """Substeps per cycle ``T`` [s] per joint, (6,) int64, so that ``omega_max h <= OMEGA_H`` for each
    joint's own fastest rate (module docstring).

    ``jl`` [kg m^2] (6,) or (M, 6): the smallest link inertia per joint along the motion is used;
    ``friction`` the LoopFriction whose bristle stiffness and damping must be resolved too (with
    ``DriveFlags.FRICTION``).
    """
    jl_min = np.min(np.atleast_2d(np.asarray(jl, float)), axis=0)
    w_gear = np.sqrt(p.c * (1.0 / p.jm + 1.0 / jl_min))
    rate_d = p.d * (1.0 / p.jm + 1.0 / jl_min)
    rate_ctl = p.kp / p.jm
    cand = [w_gear, rate_d, rate_ctl]
    if flags & DriveFlags.FRICTION and friction is not None:
        s0, damp = bristle_rates(friction)
        j_side = np.where(p.side == FrictionSide.MOTOR, p.jm, jl_min)
        cand += [np.sqrt(s0 / j_side), damp / j_side]
    w = np.max(np.stack(cand), axis=0)
    return np.maximum(1, np.ceil(w * T / OMEGA_H)).astype(np.int64)


def linear_modes(p: DriveParams, jl: float, j: int) -> list[tuple[float, float]]:
    """Poles of joint ``j``'s (0-based) closed drive loop, linearised: no friction, no play.

    The feed-forward and the windup compensation act on the reference only and leave the poles
    alone. States ``(theta, omega, q, qd, integ)`` of the equations in the module docstring with
    ``u = kp (kv (r - theta) - omega) + integ``, ``integ_d = ki (kv (r - theta) - omega)``.

    Parameters
    ----------
    p : DriveParams
    jl : float
        Link inertia [kg m^2].
    j : int
        Joint, 0-based.

    Returns
    -------
    list of (float, float)
        Per pole pair (and per real pole) its natural frequency ``|s| / 2 pi`` [Hz] and damping
        ratio ``-Re s / |s|`` [-], by frequency.
    """
    jm, c, d = float(p.jm[j]), float(p.c[j]), float(p.d[j])
    kv, kp, ki = float(p.kv[j]), float(p.kp[j]), float(p.ki[j])
    a = np.zeros((5, 5))
    a[0, 1] = 1.0
    a[1] = [-(kp * kv + c) / jm, -(kp + d) / jm, c / jm, d / jm, 1.0 / jm]
    a[2, 3] = 1.0
    a[3] = [c / jl, d / jl, -c / jl, -d / jl, 0.0]
    a[4] = [-ki * kv, -ki, 0.0, 0.0, 0.0]
    ev = np.linalg.eigvals(a)
    # the integrator-free limit has a pole at 0 (the position of the whole drive when kv = 0)
    return sorted((float(abs(e) / (2 * math.pi)), float(-e.real / abs(e)) if abs(e) > 0 else 1.0)
                  for e in ev if e.imag >= 0.0)


@njit(cache=True)
def _twist_rows(c, t1, p1, tau):
    out = np.empty_like(tau)
    for i in range(tau.shape[0]):
        for j in range(tau.shape[1]):
            out[i, j] = elastic_twist(c[j], t1[j], p1[j], tau[i, j])
    return out


def elastic_twist_array(p: DriveParams, tau) -> np.ndarray:
    """:func:`elastic_twist` of each joint's gear for static torques ``tau`` [Nm] (..., 6): twist [rad]."""
    tau = np.asarray(tau, float)
    rows = np.ascontiguousarray(tau.reshape(-1, N_AXES))
    c, t1, p1 = (np.ascontiguousarray(np.broadcast_to(np.asarray(v, float), (N_AXES,))) for v in (p.c, p.t1, p.p1))
    return _twist_rows(c, t1, p1, rows).reshape(tau.shape)


def as_substeps(substeps) -> np.ndarray:
    """Substeps per joint (6,) int64 from an int or six ints; ``ValueError`` below 1."""
    n = np.broadcast_to(np.asarray(substeps), (N_AXES,))
    if not np.all(n == np.floor(n)) or np.any(n < 1):
        raise ValueError(f"substeps must be integers >= 1, got {substeps!r}")
    return np.ascontiguousarray(n, dtype=np.int64)


def drive_params(robot, *, gains=None) -> DriveParams:
    """The :class:`DriveParams` of a robot: rotor inertia, gear stiffness/damping/play, servo gains, friction side.

    The friction models are separate: :func:`simulate.robot.friction.loop_friction`.

    Parameters
    ----------
    robot : simulate.robot.model.Robot
        Needs its ``[joint.drive]`` tables (``robot.drive``).
    gains : simulate.robot.model.ServoGains, optional
        Replaces ``robot.servo``.

    Raises
    ------
    InputError
        No ``[joint.drive]`` table or an infinite (rigid) stiffness.
    """
    if robot.drive is None:
        raise InputError("the drive model needs a [joint.drive] table per joint", source=robot.source or None,
                         field="joint[1].drive")
    for j in range(N_AXES):
        if not math.isfinite(robot.stiffness[j]):
            raise InputError("the drive model needs a finite gear stiffness", source=robot.source or None,
                             field=f"joint[{j + 1}].stiffness")
    gs = gains if gains is not None else robot.servo
    dr = robot.drive
    # the soft zone beyond the play: up to the torque the lost motion is quoted at, over half of the
    # lost motion that the play does not take (the catalogue's lost motion includes the play)
    lm = np.array(dr.lost_motion, float)
    p1 = np.where(lm > 0, 0.5 * (lm - np.array(robot.backlash, float)), 0.0)
    t1 = np.where(p1 > 0, np.array(dr.lost_motion_torque, float), 0.0)
    return DriveParams(
        jm=np.array(robot.rotor_inertia, float), c=np.array(robot.stiffness, float), d=np.array(dr.damping, float),
        b=np.array(robot.backlash, float), kv=np.array(gs.kv, float), kp=np.array(gs.kp_vel, float),
        ki=np.array(gs.ki_vel, float), ffv=np.array(gs.ff_vel, float), fft=np.array(gs.ff_tau, float),
        side=np.array(dr.friction_side, dtype=np.int64), t1=t1, p1=p1)


def drive_flags(*, friction: bool = True, backlash: bool = True, ff_friction: bool = False) -> DriveFlags:
    """:meth:`DriveFlags.default` with friction, play and friction feed-forward switched as given."""
    flags = DriveFlags.default()
    if not friction:
        flags &= ~DriveFlags.FRICTION
    if not backlash:
        flags &= ~DriveFlags.BACKLASH
    if ff_friction:
        flags |= DriveFlags.FF_FRICTION
    return flags


def drive_friction(robot, friction=None, *, scale: float = 1.0, flags: DriveFlags | None = None):
    """The LoopFriction the drives use: ``friction`` or the robot file's, levels times ``scale``.

    Raises ``InputError`` (``friction-scale``) for a scale of an LSTM model's level, and
    (``ff-friction``) for friction feed-forward on a joint whose model has no static curve (LSTM).
    """
    from simulate.robot.friction import loop_friction
    from simulate.robot.loop_friction import FrictionKind, scale_levels

    flags = DriveFlags.default() if flags is None else flags
    fp = friction if friction is not None else loop_friction(robot)[0]
    try:
        fp = scale_levels(fp, float(scale))
    except ValueError as exc:
        raise InputError(str(exc), field="friction-scale") from None
    if flags & DriveFlags.FF_FRICTION and np.any(np.asarray(fp.kind) == FrictionKind.LSTM):
        raise InputError("friction feed-forward needs a static friction curve; an LSTM model has none",
                         field="ff-friction")
    return fp


def load_torques(robot, q, qd, qdd, *, wrench_tcp=None, payload=None):
    """Load torque on each link and the link inertia, from the arm state (Newton-Euler).

    ``tau_load_j = [M(q) qdd + C(q, qd) qd + g(q) - J^T w]_j - M_jj(q) qdd_j``: everything the link
    side of gear j must carry except its own inertia, which the drive integrates (``J_l = M_jj``,
    rotor excluded).

    Parameters
    ----------
    robot : Robot
    q, qd, qdd : array_like (N, 6)
        Link positions [rad], velocities [rad/s], accelerations [rad/s^2].
    wrench_tcp : array_like (N, 6) or (6,), optional
        Process wrench on the tool at the TCP, base axes ``[F; M]`` [N, Nm].
    payload : simulate.robot.dynamics.Payload, optional

    Returns
    -------
    tau_load : ndarray (N, 6) [Nm]
    jl : ndarray (N, 6) [kg m^2]
    """
    from simulate.robot.dynamics import mass_matrix, rnea

    q = np.atleast_2d(np.asarray(q, float))
    qdd = np.atleast_2d(np.asarray(qdd, float))
    tau = np.atleast_2d(rnea(robot, q, qd, qdd, wrench_tcp=wrench_tcp, payload=payload, rotor=False))
    M = mass_matrix(robot, q, payload=payload, rotor=False).reshape(-1, 6, 6)
    jl = np.diagonal(M, axis1=1, axis2=2).copy()
    return tau - jl * qdd, jl


#: Rigid-body data for :func:`load_torque_step`: dh (6, 4) [a, alpha, d, theta_offset]; mass (6,) [kg];
#: com (6, 3) [m]; inertia (6, 3, 3) [kg m^2] (link frames, tool and payload merged into link 6);
#: g0 (3,) gravity [m/s^2]; zero (6,), rows (8, 6) x 3 and out (8, 6): work arrays.
DynParams = namedtuple("DynParams", "dh mass com inertia g0 zero q_rows qd_rows qdd_rows out")


def dyn_params(robot, payload=None) -> DynParams:
    """The :class:`DynParams` of a robot (optional payload on the flange, ``dynamics.Payload``)."""
    from simulate.robot.dynamics import GRAVITY, link_parameters

    mass, com, inertia = link_parameters(robot, payload)
    dh = np.ascontiguousarray(np.stack([robot.a, robot.alpha, robot.d, robot.theta_offset], axis=1), float)
    return DynParams(dh=dh, mass=np.ascontiguousarray(mass), com=np.ascontiguousarray(com),
                     inertia=np.ascontiguousarray(inertia), g0=np.array(GRAVITY, float), zero=np.zeros(N_AXES),
                     q_rows=np.zeros((8, N_AXES)), qd_rows=np.zeros((8, N_AXES)), qdd_rows=np.zeros((8, N_AXES)),
                     out=np.zeros((8, N_AXES)))


def dyn_params_empty() -> DynParams:
    """A :class:`DynParams` of no robot (all zero): a placeholder of the right types."""
    z = np.zeros((8, N_AXES))
    return DynParams(dh=np.zeros((N_AXES, 4)), mass=np.zeros(N_AXES), com=np.zeros((N_AXES, 3)),
                     inertia=np.zeros((N_AXES, 3, 3)), g0=np.zeros(3), zero=np.zeros(N_AXES), q_rows=z.copy(),
                     qd_rows=z.copy(), qdd_rows=z.copy(), out=z.copy())


@njit(cache=True)
def load_torque_step(dyn, q, qd, qdd, tau_process, out_load, out_jl):
    """Per-step :func:`load_torques` for a compiled loop (one Newton-Euler call of 8 rows).

    ``out_load = [M q_dd + C q_d + g]_j - M_jj q_dd_j + tau_process_j`` [Nm] and ``out_jl = M_jj``
    [kg m^2] at the state ``q, qd, qdd`` (6,); ``tau_process`` (6,) is the joint torque the process
    wrench demands, ``-J^T w`` [Nm] (the caller has J). Rows: the state; ``q, 0, e_j`` (j = 1..6);
    ``q, 0, 0``, so ``M_jj = row_j[j] - g_j``. Not thread-safe (``dyn`` holds the work arrays).
    """
    for r in range(8):
        for i in range(N_AXES):
            dyn.q_rows[r, i] = q[i]
            dyn.qd_rows[r, i] = qd[i] if r == 0 else 0.0
            dyn.qdd_rows[r, i] = qdd[i] if r == 0 else (1.0 if r == i + 1 else 0.0)
    _rnea_kernel(dyn.dh, dyn.mass, dyn.com, dyn.inertia, dyn.zero, dyn.q_rows, dyn.qd_rows, dyn.qdd_rows,
                 dyn.g0, dyn.out)
    for j in range(N_AXES):
        mjj = dyn.out[j + 1, j] - dyn.out[7, j]
        out_jl[j] = mjj
        out_load[j] = dyn.out[0, j] - mjj * qdd[j] + tau_process[j]


@dataclass(frozen=True, eq=False)
class DriveResult:
    """Simulated drives at the command times (arrays (M, 6) unless noted, joint side).

    Attributes
    ----------
    t : ndarray (M,)
        Time [s].
    q_cmd : ndarray
        Commanded link positions [rad].
    q : ndarray
        Link positions [rad] (what the kinematics sees).
    theta : ndarray
        Motor positions divided by the gear ratio [rad] (the encoder).
    tau_gear : ndarray
        Transmitted gear torque [Nm].
    tau_friction : ndarray
        Friction torque [Nm] (on the side ``friction_side`` says).
    tau_motor : ndarray
        Motor torque, joint side [Nm].
    contact : ndarray of int8
        :class:`Contact` per sample: +1/-1 flank, 0 in the play.
    tau_load : ndarray
        Load torque on the link that was applied [Nm].
    substeps : ndarray (6,) of int
        Substeps per cycle used, per joint.
    flags : DriveFlags
    """

    t: np.ndarray
    q_cmd: np.ndarray
    q: np.ndarray
    theta: np.ndarray
    tau_gear: np.ndarray
    tau_friction: np.ndarray
    tau_motor: np.ndarray
    contact: np.ndarray
    tau_load: np.ndarray
    substeps: np.ndarray
    flags: DriveFlags

    @property
    def error(self) -> np.ndarray:
        """Link following error ``q_cmd - q`` [rad]."""
        return self.q_cmd - self.q

    def tcp_error(self, robot) -> np.ndarray:
        """Path error at the TCP, ``p(q) - p(q_cmd)`` (M, 3) [m], base frame."""
        from simulate.robot.kinematics import fk

        return fk(robot, self.q)[:, :3, 3] - fk(robot, self.q_cmd)[:, :3, 3]


def command_velocity(t, q) -> np.ndarray:
    """Velocities of samples ``q`` at times ``t`` by second-order central differences [rad/s]."""
    return np.gradient(q, t, axis=0, edge_order=2) if len(t) > 2 else np.gradient(q, t, axis=0)


def simulate_drive(robot, t, q_cmd, *, tau_load=None, tau_model=None, link_inertia=None,
                   flags: DriveFlags | None = None, friction: bool = True, backlash: bool = True,
                   ff_friction: bool = False, params: DriveParams | None = None, loop_friction=None,
                   friction_scale: float = 1.0, substeps: int | None = None) -> DriveResult:
    """Run the six drives along a commanded joint trajectory (loads given or along the command).

    Parameters
    ----------
    robot : Robot
    t : array_like (M,)
        Command times [s], strictly increasing (normally the 2 ms cycle).
    q_cmd : array_like (M, 6)
        Commanded link positions [rad].
    tau_load : array_like (M, 6), optional
        Load torque on the links [Nm]; default :func:`load_torques` along the command (gravity and
        inertial coupling; the command is the state where the arm is meant to be).
    tau_model : array_like (M, 6), optional
        Load the NC's torque feed-forward knows [Nm]; default ``tau_load`` (a process force would
        be in ``tau_load`` only).
    link_inertia : array_like (M, 6) or (6,), optional
        ``J_l`` [kg m^2]; default ``M_jj`` along the command.
    flags : DriveFlags, optional
        Overrides ``friction``, ``backlash``, ``ff_friction`` (default :meth:`DriveFlags.default`).
    friction, backlash, ff_friction : bool
        Switch friction, gear play and friction feed-forward.
    params : DriveParams, optional
        Replaces :func:`drive_params` of the robot.
    loop_friction : LoopFriction, optional
        Each joint's friction model; default the robot file's (:func:`drive_friction`).
    friction_scale : float
        Factor on every joint's Coulomb and static levels [-].
    substeps : int or array_like (6,), optional
        Substeps per cycle (per joint); default :func:`substeps_for`.

    Returns
    -------
    DriveResult
    """
    from simulate.robot.loop_friction import new_state as friction_state

    t = np.ascontiguousarray(np.asarray(t, float))
    q = np.ascontiguousarray(np.asarray(q_cmd, float))
    if t.ndim != 1 or q.shape != (t.shape[0], N_AXES):
        raise ValueError(f"t (M,) and q_cmd (M, 6) expected, got {t.shape} and {q.shape}")
    if t.shape[0] < 2 or not np.all(np.diff(t) > 0):
        raise ValueError("t must be strictly increasing with at least 2 samples")
    if flags is None:
        flags = drive_flags(friction=friction, backlash=backlash, ff_friction=ff_friction)
    flags = DriveFlags(flags)
    p = params if params is not None else drive_params(robot)
    fp = drive_friction(robot, loop_friction, scale=friction_scale, flags=flags)
    v = np.ascontiguousarray(command_velocity(t, q))
    a = np.ascontiguousarray(command_velocity(t, v))
    if tau_load is None or link_inertia is None:
        tl, jl0 = load_torques(robot, q, v, a)
    tl = np.ascontiguousarray(np.broadcast_to(np.asarray(tau_load if tau_load is not None else tl, float), q.shape))
    tm = (tl if tau_model is None
          else np.ascontiguousarray(np.broadcast_to(np.asarray(tau_model, float), q.shape)))
    jl = np.ascontiguousarray(np.broadcast_to(np.asarray(link_inertia if link_inertia is not None else jl0, float),
                                              q.shape))
    if not np.all(jl > 0):
        raise ValueError("link inertia must be > 0")
    T = float(np.max(np.diff(t)))
    n_sub = as_substeps(substeps) if substeps is not None else substeps_for(p, jl, T, int(flags), fp)
    m = t.shape[0]
    out = np.empty((5, m, N_AXES))
    oc = np.empty((m, N_AXES), dtype=np.int8)
    st = new_state()
    ff = nc_friction(fp, t, q, v, tm + jl * a, int(flags))
    _run_kernel(p, fp, st, friction_state(fp), np.stack([q, v, a]), tl, tm, jl, ff, t, n_sub, int(flags), out, oc)
    return DriveResult(t=t, q_cmd=q, q=out[0], theta=out[1], tau_gear=out[2], tau_friction=out[3], tau_motor=out[4],
                       contact=oc, tau_load=tl, substeps=n_sub, flags=flags)
