"""Every fitted friction model as compiled "loop friction", evaluated inside the coupled machining loop.

The coupled loop (:mod:`simulate.machining.simulation`) steps the two-mass drives every substep
(:func:`simulate.robot.drive.drive_step`); each joint's friction torque comes from ONE numba dispatch
function, evaluated on the simulated motion of that substep (joint or motor side, as the drive
says)::

    tau_F = friction_torque(p, j, state, v, q, load, dt)

    p      LoopFriction    parameters of all six joints (named tuple of arrays, :func:`loop_friction`)
    j      int             joint index 0..5
    state  (6, S) float    per-joint friction state, updated in place (:func:`new_state`)
    v      float           joint velocity now [rad/s]
    q      float           joint position now [rad]
    load   float           torque the gearbox carries now [Nm] (``tau_load`` of the records)
    dt     float           time since the previous call for this joint [s] (ignored on the first call)
    -> friction torque now [Nm], opposing the motion (the drive's load is ``+tau_F``)

The call semantics are those of the models' own ``predict`` on a record: the state is advanced over
the interval since the previous call with the model's own discretisation, then the friction of the
current sample is returned. Fed a record's samples (``dt`` the sample interval) it reproduces
``predict_friction`` (tests/robot/test_loop_friction.py: within 1% of each model's torque RMS; all
but the LSTM to round-off). ``predict`` adds ``J*qdd + c`` (or ``tau_rb``), the rigid-body torque,
which in the loop is the dynamics' own business, so only the friction enters.

Per model type (:class:`FrictionKind`), read from the saved model folder (``params.json`` and
``network.pt``; the fitted attributes, without importing :mod:`identify.models`):

- ``coulomb-viscous``, ``stribeck``: closed forms of the velocity.
- ``lugre`` (and a robot file's inline LuGre): exact bristle update with the velocity of the previous
  sample held over the interval, Stribeck level (``identify.models.lugre_kernel``).
- ``lugre-extended``: LuGre with the level scaled by the load (``|load| - load_ref``), the direction
  asymmetry and the position ripple. The loop has no thermal model, so the temperature is the
  model's reference temperature (``dT = 0``). The inertia and drift extensions are rigid-body / sensor
  terms, not friction, and stay out.
- ``greybox``: LuGre whose level ``g(v)`` is the fitted MLP (log-compressed speed, 10 sigmoids,
  softplus output), evaluated exactly in numba; the state advances with the trapezoid velocity of the
  interval, as the model's scan does.
- ``residual``: LuGre plus its MLP (3-10-10-1, LeakyReLU) on velocity, normalised bristle state and
  LuGre torque, weights evaluated in numba.
- ``lstm``: the LSTM cell and its tanh read-out evaluated in numba from the saved weights, the hidden
  state carried. A black-box sequence model has no time constant of its own: it is stepped at the
  sample interval it was trained at (:data:`simulate.defaults.LEARNED_SAMPLE_PERIOD`), its output held
  in between; the velocity, position (play-operator features) and acceleration (backward difference of
  the velocity over its interval) are taken from the simulated joint at each of its samples. Its own
  ``predict`` restarts the LSTM every ``window`` samples after ``warmup`` samples of history (the
  layout it was trained and scored with); the loop runs the same overlapping windows side by side (at
  most ``warmup // window + 2`` cells), so the torque is the model's, not a continuously run variant.

torch is imported only to read a learned model's ``network.pt``.
"""
from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Sequence
from enum import IntEnum, IntFlag
from pathlib import Path

import numpy as np
from numba import njit

from identify.errors import InputError, read_json
from simulate import defaults


class FrictionKind(IntEnum):
    """The loop-friction form of a joint."""

    NONE = 0
    COULOMB_VISCOUS = 1
    STRIBECK = 2
    LUGRE = 3
    LUGRE_EXTENDED = 4
    GREYBOX = 5
    RESIDUAL = 6
    LSTM = 7


#: Saved model name (``params.json`` "model") -> kind.
MODEL_KINDS = {"coulomb-viscous": FrictionKind.COULOMB_VISCOUS, "stribeck": FrictionKind.STRIBECK,
               "lugre": FrictionKind.LUGRE, "lugre-extended": FrictionKind.LUGRE_EXTENDED,
               "greybox": FrictionKind.GREYBOX, "residual": FrictionKind.RESIDUAL, "lstm": FrictionKind.LSTM}


class Extension(IntFlag):
    """Extensions of a ``lugre-extended`` model that act on the friction in the loop."""

    LOAD = 1
    ASYMMETRY = 2
    POSITION = 4
    TEMPERATURE = 8


# the members as plain ints for the compiled code (numba does not type IntFlag arithmetic)
EXT_LOAD = int(Extension.LOAD)
EXT_ASYMMETRY = int(Extension.ASYMMETRY)
EXT_POSITION = int(Extension.POSITION)


# scalar parameter slots (columns of LoopFriction.scal)
S0, S1, NU, FC, FS, VS, DELTA, MU = range(8)
K_LOAD, LOAD_REF, ASYM, RIP_SIN, RIP_COS, RIP_ORDER, EXT_FLAGS, K_DRY_TEMP = range(8, 16)
V_MAX, V_REF, TAU_SCALE, RES_SCALE, A_SCALE, PERIOD, TANH_V, LOG_V = range(16, 24)
N_SCAL = 24
# integer dimensions (columns of LoopFriction.dims)
D_IN, D_H1, D_H2, D_PLAY, D_WINDOW, D_WARMUP, D_SLOTS = range(7)
N_DIMS = 7
# state slots (columns of the state array); the LSTM's cells and scratch follow ST_LSTM
ST_INIT, ST_VPREV, ST_Z, ST_GPREV, ST_K, ST_ACC, ST_OUT, ST_VLSTM = range(8)
ST_LSTM = 8
#: Smallest multiplicative level factor of the extended model (as identify.models.extended).
LEVEL_FLOOR = 0.05

#: Compiled parameters of the six joints' friction; arrays indexed by joint first.
LoopFriction = namedtuple("LoopFriction", [
    "kind",   # (6,) int64 FrictionKind
    "scal",   # (6, N_SCAL) scalar parameters (slots above)
    "dims",   # (6, N_DIMS) int64 network dimensions
    "w1", "b1", "w2", "b2", "w3", "b3",   # MLPs: greybox level (w1, b1, w2, b2); residual (all); lstm head (w1..b2)
    "wih", "whh", "bl",   # LSTM cell: (6, 4H, n_in), (6, 4H, H), (6, 4H) (gate order i, f, g, o)
    "widths",  # (6, P) play-operator half-widths [rad]
])


def _empty() -> dict:
    return {"kind": int(FrictionKind.NONE), "scal": np.zeros(N_SCAL), "dims": np.zeros(N_DIMS, np.int64)}


def state_size(p: LoopFriction) -> int:
    """Columns of the state array the joints of ``p`` need."""
    need = ST_LSTM
    for j in range(6):
        if p.kind[j] == FrictionKind.RESIDUAL:
            need = max(need, ST_LSTM + int(p.dims[j, D_H1]))
        if p.kind[j] == FrictionKind.LSTM:
            n_in, hid, head, slots = (int(p.dims[j, d]) for d in (D_IN, D_H1, D_H2, D_SLOTS))
            need = max(need, ST_LSTM + int(p.dims[j, D_PLAY]) + slots * 2 * hid + n_in + 4 * hid + head)
    return need


def new_state(p: LoopFriction) -> np.ndarray:
    """A fresh (not yet initialised) friction state for the six joints, (6, :func:`state_size`)."""
    return np.zeros((6, state_size(p)))


# --------------------------------------------------------------------------- compiled evaluation
@njit(cache=True, inline="always")
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True, inline="always")
def _stribeck(v, fc, fs, vs, delta):
    x = abs(v) / vs
    if x == 0.0:
        return fs
    return fc + (fs - fc) * math.exp(-math.exp(delta * math.log(x)))


@njit(cache=True, inline="always")
def _softplus(x):
    return x if x > 20.0 else math.log1p(math.exp(x))


@njit(cache=True)
def _greybox_level(p, j, v):
    """The grey-box MLP level g(v) [Nm] (identify.models.greybox.StaticLevelNet)."""
    sc = p.scal[j]
    x = math.log1p(abs(v) / sc[V_REF]) / math.log1p(sc[V_MAX] / sc[V_REF])
    acc = p.b2[j, 0]
    for i in range(p.dims[j, D_H1]):
        acc += p.w2[j, 0, i] / (1.0 + math.exp(-(p.w1[j, i, 0] * x + p.b1[j, i])))
    return sc[TAU_SCALE] * (_softplus(acc) + 1e-6)


@njit(cache=True)
def _lugre_step(p, j, st, v, g, dt, nu):
    """Bristle state advanced to now (previous velocity and level held, exact update), friction now."""
    s0 = p.scal[j, S0]
    if st[j, ST_INIT] == 0.0:
        z = g * _sign(v) / s0
        st[j, ST_INIT] = 1.0
    else:
        z = st[j, ST_Z]
        vp = st[j, ST_VPREV]
        if vp != 0.0:
            gp = st[j, ST_GPREV]
            zss = gp * _sign(vp) / s0
            z = zss + (z - zss) * math.exp(-s0 * abs(vp) * dt / gp)
    st[j, ST_Z] = z
    st[j, ST_VPREV] = v
    st[j, ST_GPREV] = g
    return s0 * z + p.scal[j, S1] * (v - s0 * abs(v) * z / g) + nu * v


@njit(cache=True)
def _greybox(p, j, st, v, dt):
    sc = p.scal[j]
    s0 = sc[S0]
    g = _greybox_level(p, j, v)
    if st[j, ST_INIT] == 0.0:
        w = g * _sign(v)
        st[j, ST_INIT] = 1.0
    else:
        w = st[j, ST_Z]
        vi = 0.5 * (st[j, ST_VPREV] + v)   # the interval's velocity: trapezoid, as the model's scan
        if vi != 0.0:
            gi = _greybox_level(p, j, vi)
            a = math.exp(-s0 * abs(vi) * dt / gi)
            w = a * w + (1.0 - a) * gi * _sign(vi)
    st[j, ST_Z] = w
    st[j, ST_VPREV] = v
    return w + sc[S1] * (v - abs(v) * w / g) + sc[NU] * v


@njit(cache=True)
def _residual(p, j, st, v, dt):
    sc = p.scal[j]
    g = _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA])
    f = _lugre_step(p, j, st, v, g, dt, sc[NU])
    z = st[j, ST_Z]
    x0 = _sign(v) * math.log1p(abs(v) / sc[V_REF]) / math.log1p(sc[V_MAX] / sc[V_REF])
    x1 = sc[S0] * z / g
    x2 = f / sc[TAU_SCALE]
    n1, n2 = p.dims[j, D_H1], p.dims[j, D_H2]
    out = p.b3[j, 0]
    h1 = st[j, ST_LSTM:ST_LSTM + n1]   # scratch columns of the state
    for i in range(n1):
        a = p.b1[j, i] + p.w1[j, i, 0] * x0 + p.w1[j, i, 1] * x1 + p.w1[j, i, 2] * x2
        h1[i] = a if a > 0.0 else 0.01 * a
    for i in range(n2):
        a = p.b2[j, i]
        for k in range(n1):
            a += p.w2[j, i, k] * h1[k]
        out += p.w3[j, 0, i] * (a if a > 0.0 else 0.01 * a)
    return f + sc[RES_SCALE] * out


@njit(cache=True)
def _extended(p, j, st, v, q, load, dt):
    sc = p.scal[j]
    flags = int(sc[EXT_FLAGS])
    mult = 1.0
    if flags & EXT_LOAD:
        mult *= max(1.0 + sc[K_LOAD] * (abs(load) - sc[LOAD_REF]), LEVEL_FLOOR)
    # temperature (flag 8): at the model's reference temperature, dT = 0: factors 1 (module docstring)
    if (flags & EXT_ASYMMETRY) and v < 0.0:
        mult *= 1.0 + sc[ASYM]
    g = _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA]) * mult
    f = _lugre_step(p, j, st, v, g, dt, sc[NU])
    if flags & EXT_POSITION:
        n = sc[RIP_ORDER]
        f += sc[RIP_SIN] * math.sin(n * q) + sc[RIP_COS] * math.cos(n * q)
    return f


@njit(cache=True, inline="always")
def _sigmoid(x):
    return 1.0 / (1.0 + math.exp(-x))


@njit(cache=True)
def _lstm_cell(p, j, st, hc, x, n_in, hid, gates):
    """One LSTM step of the cell whose (h, c) start at state column ``hc``."""
    for r in range(4 * hid):
        a = p.bl[j, r]
        for k in range(n_in):
            a += p.wih[j, r, k] * x[k]
        for k in range(hid):
            a += p.whh[j, r, k] * st[j, hc + k]
        gates[r] = a
    for k in range(hid):
        i_g = _sigmoid(gates[k])
        f_g = _sigmoid(gates[hid + k])
        g_g = math.tanh(gates[2 * hid + k])
        o_g = _sigmoid(gates[3 * hid + k])
        c = f_g * st[j, hc + hid + k] + i_g * g_g
        st[j, hc + hid + k] = c
        st[j, hc + k] = o_g * math.tanh(c)


@njit(cache=True)
def _lstm_sample(p, j, st, v, q, qdd, first):
    """One LSTM sample: features, the windows' cells, the read-out of the scoring window [Nm]."""
    sc = p.scal[j]
    n_in, hid, head = p.dims[j, D_IN], p.dims[j, D_H1], p.dims[j, D_H2]
    n_play, window, warmup, slots = p.dims[j, D_PLAY], p.dims[j, D_WINDOW], p.dims[j, D_WARMUP], p.dims[j, D_SLOTS]
    o_play = ST_LSTM
    o_cells = o_play + n_play
    o_x = o_cells + slots * 2 * hid
    o_g = o_x + n_in
    o_head = o_g + 4 * hid
    x = st[j, o_x:o_x + n_in]
    gates = st[j, o_g:o_g + 4 * hid]
    vn = v / sc[V_MAX]
    x[0] = vn
    x[1] = math.tanh(vn / sc[TANH_V])
    x[2] = _sign(vn) * math.log1p(abs(vn) / sc[LOG_V]) / math.log1p(1.0 / sc[LOG_V])
    x[3] = qdd / sc[A_SCALE]
    for m in range(n_play):
        r = p.widths[j, m]
        y = q if first else st[j, o_play + m]
        if y < q - r:
            y = q - r
        elif y > q + r:
            y = q + r
        st[j, o_play + m] = y
        x[4 + m] = (q - y) / r
    k = int(st[j, ST_K])
    w_lo = k // window
    w_hi = (k + warmup) // window
    for w in range(w_lo, w_hi + 1):
        hc = o_cells + (w % slots) * 2 * hid
        start = w * window - warmup
        if start == k or (first and start < 0):
            for c in range(2 * hid):
                st[j, hc + c] = 0.0
            if first:   # history before the record: at rest at the first sample (as the model pads)
                for _ in range(-start):
                    _lstm_cell(p, j, st, hc, x, n_in, hid, gates)
        _lstm_cell(p, j, st, hc, x, n_in, hid, gates)
    hc = o_cells + (w_lo % slots) * 2 * hid
    out = p.b2[j, 0]
    for i in range(head):
        a = p.b1[j, i]
        for c in range(hid):
            a += p.w1[j, i, c] * st[j, hc + c]
        for c in range(n_in):
            a += p.w1[j, i, hid + c] * x[c]
        st[j, o_head + i] = math.tanh(a)
        out += p.w2[j, 0, i] * st[j, o_head + i]
    st[j, ST_K] = k + 1
    return sc[TAU_SCALE] * out


@njit(cache=True)
def _lstm(p, j, st, v, q, dt):
    period = p.scal[j, PERIOD]
    if st[j, ST_INIT] == 0.0:
        st[j, ST_INIT] = 1.0
        st[j, ST_ACC] = 0.0
        st[j, ST_VLSTM] = v
        st[j, ST_OUT] = _lstm_sample(p, j, st, v, q, 0.0, True)
        return st[j, ST_OUT]
    acc = st[j, ST_ACC] + dt
    if acc >= period * (1.0 - 1e-9):   # one of its samples is due: step it with the joint's motion now
        acc -= period
        qdd = (v - st[j, ST_VLSTM]) / period
        st[j, ST_VLSTM] = v
        st[j, ST_OUT] = _lstm_sample(p, j, st, v, q, qdd, False)
    st[j, ST_ACC] = acc
    return st[j, ST_OUT]


@njit(cache=True)
def friction_torque(p, j, state, v, q, load, dt):
    """Friction torque [Nm] of joint ``j`` now (module docstring: the loop-friction interface).

    Parameters
    ----------
    p : LoopFriction
    j : int
        Joint index 0..5.
    state : ndarray (6, S)
        Friction state (:func:`new_state`), updated in place.
    v : float
        Joint velocity [rad/s].
    q : float
        Joint position [rad].
    load : float
        Gearbox load torque [Nm].
    dt : float
        Time since the previous call for this joint [s].
    """
    kind = p.kind[j]
    sc = p.scal[j]
    if kind == 3:   # FrictionKind.LUGRE
        return _lugre_step(p, j, state, v, _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA]), dt, sc[NU])
    if kind == 5:   # GREYBOX
        return _greybox(p, j, state, v, dt)
    if kind == 1:   # COULOMB_VISCOUS
        return sc[MU] * _sign(v) + sc[NU] * v
    if kind == 2:   # STRIBECK
        return _sign(v) * _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA]) + sc[NU] * v
    if kind == 4:   # LUGRE_EXTENDED
        return _extended(p, j, state, v, q, load, dt)
    if kind == 6:   # RESIDUAL
        return _residual(p, j, state, v, dt)
    if kind == 7:   # LSTM
        return _lstm(p, j, state, v, q, dt)
    return 0.0


@njit(cache=True)
def static_friction(p, j, v):
    """Steady-state friction curve of joint ``j`` at a held velocity ``v`` [rad/s] -> [Nm].

    The level the NC's friction feed-forward (:func:`command_friction`) reaches at a held speed:
    ``sign(v) g(v) + nu v`` for the LuGre forms and
    the grey-box (its MLP level), the closed forms of coulomb-viscous and Stribeck, the LuGre base
    of a residual model, and the direction asymmetry of a lugre-extended one (its load factor at
    the reference load). An LSTM has no static curve of its own: 0.
    """
    kind = p.kind[j]
    sc = p.scal[j]
    if kind == 1:
        return sc[MU] * _sign(v) + sc[NU] * v
    if kind == 2 or kind == 3 or kind == 6:
        return _sign(v) * _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA]) + sc[NU] * v
    if kind == 4:
        mult = 1.0 + sc[ASYM] if (int(sc[EXT_FLAGS]) & EXT_ASYMMETRY) and v < 0.0 else 1.0
        return _sign(v) * _stribeck(v, sc[FC], sc[FS], sc[VS], sc[DELTA]) * mult + sc[NU] * v
    if kind == 5:
        return _sign(v) * _greybox_level(p, j, v) + sc[NU] * v
    return 0.0


def bristle_rates(p: LoopFriction) -> tuple[np.ndarray, np.ndarray]:
    """Per joint the bristle stiffness ``s0`` [Nm/rad] and the velocity damping ``s1 + nu`` [Nm s/rad]
    an explicit integrator must resolve (0 where the form has none; an LSTM's rate is its own sample)."""
    kind = np.asarray(p.kind)
    bristle = np.isin(kind, [FrictionKind.LUGRE, FrictionKind.LUGRE_EXTENDED, FrictionKind.GREYBOX,
                             FrictionKind.RESIDUAL])
    s0 = np.where(bristle, p.scal[:, S0], 0.0)
    damp = np.where(bristle, p.scal[:, S1], 0.0) + np.where(kind != FrictionKind.LSTM, p.scal[:, NU], 0.0)
    return s0, damp


def scale_levels(p: LoopFriction, factor: float) -> LoopFriction:
    """The friction with every joint's Coulomb and static levels multiplied by ``factor`` [-].

    ``fc, fs`` of the Stribeck/LuGre forms (the residual's LuGre base), ``mu`` of coulomb-viscous,
    the whole level curve ``g(v)`` of a grey-box; viscous parts unchanged. An LSTM has no separate
    level: ``ValueError``.
    """
    if factor == 1.0:
        return p
    kind = np.asarray(p.kind)
    if np.any(kind == FrictionKind.LSTM):
        raise ValueError("an LSTM friction model has no Coulomb/static level to scale")
    scal = p.scal.copy()
    scal[:, [FC, FS, MU]] *= factor
    grey = kind == FrictionKind.GREYBOX
    scal[grey, TAU_SCALE] *= factor
    return p._replace(scal=scal)


def lugre_friction(fc, fs, vs, delta, s0, s1, nu) -> LoopFriction:
    """Six joints of LuGre friction from per-joint arrays (6,) [Nm, Nm, rad/s, -, Nm/rad, Nm s/rad, Nm s/rad]."""
    rows = []
    cols = [np.broadcast_to(np.asarray(x, float), (6,)) for x in (fc, fs, vs, delta, s0, s1, nu)]
    for j in range(6):
        row = _empty()
        row["kind"] = int(FrictionKind.LUGRE)
        row["scal"][[FC, FS, VS, DELTA, S0, S1, NU]] = [c[j] for c in cols]
        rows.append(row)
    return assemble(rows)


# --------------------------------------------------------------------------- building the parameters
def _read_doc(folder: Path) -> dict:
    p = folder / "params.json"
    if not p.exists():
        raise InputError("not a saved model folder (no params.json)", source=str(folder))
    doc = read_json(p)
    if not isinstance(doc, dict) or not all(k in doc for k in ("model", "params")):
        raise InputError("not a saved friction model (needs 'model' and 'params')", source=str(p))
    return doc


def _params(doc: dict, folder: Path, *names) -> list[float]:
    try:
        return [float(doc["params"][k]["value"]) for k in names]
    except (KeyError, TypeError, ValueError):
        missing = [k for k in names if k not in doc.get("params", {})]
        raise InputError(f"saved '{doc.get('model')}' model lacks parameter(s) {', '.join(missing) or names}",
                         source=str(folder / "params.json"), field="params") from None


def _network(folder: Path) -> dict:
    import torch  # a learned model is used: only now

    path = folder / "network.pt"
    if not path.exists():
        raise InputError("learned model folder without network.pt", source=str(folder))
    return torch.load(path, weights_only=True)


def _np(t) -> np.ndarray:
    return t.detach().cpu().double().numpy() if hasattr(t, "detach") else np.asarray(t, float)


def _softplus_np(x: float) -> float:
    return x if x > 20.0 else math.log1p(math.exp(x))


def joint_from_folder(folder: str | Path, *, sample_period: float = defaults.LEARNED_SAMPLE_PERIOD) -> dict:
    """One joint's loop friction read from a saved model folder (module docstring).

    Returns a dict of the joint's rows (``kind``, ``scal``, ``dims`` and the weight arrays it uses),
    assembled into a :data:`LoopFriction` by :func:`assemble`. ``sample_period`` [s] is the record
    interval a sequence model (LSTM) is stepped at.
    """
    folder = Path(folder)
    doc = _read_doc(folder)
    name = doc["model"]
    if name not in MODEL_KINDS:
        raise InputError(f"unknown friction model '{name}' (known: {', '.join(MODEL_KINDS)})",
                         source=str(folder / "params.json"), field="model")
    kind = MODEL_KINDS[name]
    row = _empty()
    row["kind"] = int(kind)
    sc, dims = row["scal"], row["dims"]
    if kind is FrictionKind.COULOMB_VISCOUS:
        sc[MU], sc[NU] = _params(doc, folder, "mu", "nu")
    elif kind is FrictionKind.STRIBECK:
        sc[FC], sc[FS], sc[VS], sc[DELTA], sc[NU] = _params(doc, folder, "fc", "fs", "vs", "delta", "nu")
    elif kind in (FrictionKind.LUGRE, FrictionKind.LUGRE_EXTENDED):
        sc[[S0, S1, NU, FC, FS, VS, DELTA]] = _params(doc, folder, "s0", "s1", "nu", "fc", "fs", "vs", "delta")
        if kind is FrictionKind.LUGRE_EXTENDED:
            causes = (doc.get("hyperparameters") or {}).get("causes") or []
            flags = Extension(0)
            if "load" in causes:
                flags |= Extension.LOAD
                sc[K_LOAD], sc[LOAD_REF] = _params(doc, folder, "k_load", "load_ref")
            if "asymmetry" in causes:
                flags |= Extension.ASYMMETRY
                sc[ASYM], = _params(doc, folder, "asym")
            if "position" in causes:
                flags |= Extension.POSITION
                sc[RIP_SIN], sc[RIP_COS], sc[RIP_ORDER] = _params(doc, folder, "ripple_sin", "ripple_cos",
                                                                  "ripple_order")
            if "temperature" in causes:
                flags |= Extension.TEMPERATURE
            sc[EXT_FLAGS] = float(int(flags))
    elif kind is FrictionKind.GREYBOX:
        st = _network(folder)["state"]
        sc[S0] = math.exp(float(st["log_s0"]))
        sc[S1] = float(st["s1_scale"]) * _softplus_np(float(st["raw_s1"]))
        sc[NU] = float(st["nu_scale"]) * _softplus_np(float(st["raw_nu"]))
        sc[V_MAX], sc[V_REF], sc[TAU_SCALE] = (float(st[k]) for k in ("level.v_max", "level.v_ref", "level.tau_scale"))
        w1, b1 = _np(st["level.hidden.weight"]), _np(st["level.hidden.bias"])
        w2, b2 = _np(st["level.out.weight"]), _np(st["level.out.bias"])
        dims[D_H1] = w1.shape[0]
        row.update(w1=w1, b1=b1, w2=w2, b2=b2)
    elif kind is FrictionKind.RESIDUAL:
        base = _read_doc(folder / "lugre")
        sc[[S0, S1, NU, FC, FS, VS, DELTA]] = _params(base, folder / "lugre", "s0", "s1", "nu", "fc", "fs", "vs",
                                                      "delta")
        st = _network(folder)["state"]
        sc[V_MAX] = float(st["v_max"])
        sc[V_REF] = sc[V_MAX] / 1000.0
        sc[TAU_SCALE], sc[RES_SCALE] = float(st["tau_scale"]), float(st["res_scale"])
        w1, b1 = _np(st["mlp.0.weight"]), _np(st["mlp.0.bias"])
        w2, b2 = _np(st["mlp.2.weight"]), _np(st["mlp.2.bias"])
        w3, b3 = _np(st["mlp.4.weight"]), _np(st["mlp.4.bias"])
        dims[D_IN], dims[D_H1], dims[D_H2] = 3, w1.shape[0], w2.shape[0]
        row.update(w1=w1, b1=b1, w2=w2, b2=b2, w3=w3, b3=b3)
    elif kind is FrictionKind.LSTM:
        from identify.models.sequence_features import LOG_VELOCITY, TANH_VELOCITY

        blob = _network(folder)
        if blob.get("format") != 2:
            raise InputError(f"saved by an older LSTM version (network format {blob.get('format', 1)}, expected 2): "
                             "refit the model", source=str(folder / "network.pt"), field="format")
        st = blob["state"]
        hp = doc.get("hyperparameters") or {}
        sc[V_MAX], sc[A_SCALE], sc[TAU_SCALE] = (float(st[k]) for k in ("v_scale", "a_scale", "tau_scale"))
        sc[TANH_V], sc[LOG_V] = TANH_VELOCITY, LOG_VELOCITY
        if not (sample_period > 0 and math.isfinite(sample_period)):
            raise InputError(f"sample period must be > 0 s, got {sample_period}", field="sample_period")
        sc[PERIOD] = sample_period
        widths = _np(st["play_widths"])
        wih, whh = _np(st["lstm.weight_ih_l0"]), _np(st["lstm.weight_hh_l0"])
        bl = _np(st["lstm.bias_ih_l0"]) + _np(st["lstm.bias_hh_l0"])
        hw1, hb1 = _np(st["head.0.weight"]), _np(st["head.0.bias"])
        hw2, hb2 = _np(st["head.2.weight"]), _np(st["head.2.bias"])
        window, warmup = int(hp.get("window", 150)), int(hp.get("warmup", 150))
        dims[D_IN], dims[D_H1], dims[D_H2] = wih.shape[1], whh.shape[1], hw1.shape[0]
        dims[D_PLAY], dims[D_WINDOW], dims[D_WARMUP] = widths.size, window, warmup
        dims[D_SLOTS] = warmup // window + 2
        row.update(w1=hw1, b1=hb1, w2=hw2, b2=hb2, wih=wih, whh=whh, bl=bl, widths=widths)
    return row


def joint_from_lugre(lugre) -> dict:
    """A robot file's inline LuGre parameters (``simulate.robot.model.LuGreParams``) as a joint row."""
    row = _empty()
    row["kind"] = int(FrictionKind.LUGRE)
    sc = row["scal"]
    sc[[S0, S1, NU, FC, FS, VS, DELTA]] = [lugre.s0, lugre.s1, lugre.nu, lugre.fc, lugre.fs, lugre.vs, lugre.delta]
    return row


_FIELDS = ("w1", "b1", "w2", "b2", "w3", "b3", "wih", "whh", "bl", "widths")


def assemble(rows: Sequence[dict | None]) -> LoopFriction:
    """Six joint rows (:func:`joint_from_folder`, :func:`joint_from_lugre`, or ``None`` for no friction)
    as one :data:`LoopFriction`, weight arrays zero-padded to the largest joint's shape."""
    full: list[dict] = [r if r is not None else _empty() for r in rows]
    if len(full) != 6:
        raise ValueError("six joints expected")
    arrays = {}
    for f in _FIELDS:
        shapes = [np.shape(r[f]) for r in full if f in r]
        nd = max((len(s) for s in shapes), default={"w1": 2, "w2": 2, "w3": 2, "wih": 2, "whh": 2}.get(f, 1))
        shape = tuple(max((s[i] for s in shapes if len(s) == nd), default=1) for i in range(nd))
        a = np.zeros((6,) + shape)
        for j, r in enumerate(full):
            if f in r:
                v = np.asarray(r[f], dtype=float)
                a[(j,) + tuple(slice(0, n) for n in v.shape)] = v
        arrays[f] = a
    return LoopFriction(kind=np.array([r["kind"] for r in full], np.int64),
                        scal=np.stack([r["scal"] for r in full]), dims=np.stack([r["dims"] for r in full]),
                        **arrays)


def describe(rows: Sequence[dict | None]) -> list[str]:
    """The kind name per joint (for reports)."""
    return [FrictionKind(r["kind"]).name.lower().replace("_", "-") if r is not None else "none" for r in rows]


def command_friction(p: LoopFriction, t, q, v, load) -> np.ndarray:
    """The friction torque [Nm] (N, 6) an NC's friction model predicts along the command: each joint's
    model run along the commanded velocity ``v`` [rad/s], position ``q`` [rad] and gearbox load ``load``
    [Nm] (N, 6) at ``t`` (N,) [s] with its own dynamics (:func:`friction_series`, fresh state); an LSTM
    contributes nothing (no model an NC could run; :func:`static_friction` gives it 0 too).

    Why not the steady curve :func:`static_friction` at the commanded velocity: that steps by twice the
    friction level wherever the commanded velocity crosses zero, also where a nearly still joint's
    command only wiggles within the friction's pre-sliding range (a corrected program's small offsets
    on a wrist axis), so a feed-forward of it flips the motor torque and, through the gear windup, the
    setpoint back and forth. A dynamic model reverses only with the motion (Canudas de Wit, Olsson,
    Åström, Lischinsky, *A new model for control of systems with friction*, IEEE TAC 40(3), 1995:
    friction compensation with the model's own state), as a controller's friction feed-forward ramps
    its level in over a small velocity (ABB's servo tuning ``TUNE_FRIC_LEV`` / ``TUNE_FRIC_RAMP``).
    At a held speed it equals the steady curve."""
    t = np.asarray(t, float)
    q = np.ascontiguousarray(q, dtype=float)
    v = np.ascontiguousarray(v, dtype=float)
    load = np.ascontiguousarray(np.broadcast_to(np.asarray(load, float), v.shape))
    out = np.zeros(v.shape)
    if len(t) == 0:
        return out
    dt = np.diff(t, prepend=t[0])
    state = new_state(p)
    for j in range(6):
        if p.kind[j] not in (FrictionKind.NONE, FrictionKind.LSTM):
            out[:, j] = friction_series(p, j, state, np.ascontiguousarray(v[:, j]), np.ascontiguousarray(q[:, j]),
                                        np.ascontiguousarray(load[:, j]), dt)
    return out


@njit(cache=True)
def friction_series(p, j, state, v, q, load, dt):
    """:func:`friction_torque` along a motion: samples ``v`` [rad/s], ``q`` [rad], ``load`` [Nm], ``dt[k]``
    the time [s] from sample k-1 to k; returns the friction [Nm] per sample (for tests and benchmarks)."""
    out = np.empty(v.shape[0])
    for k in range(v.shape[0]):
        out[k] = friction_torque(p, j, state, v[k], q[k], load[k], dt[k])
    return out
