"""Virtual circular test (ISO 230-4, ballbar) of the robot: path, simulation, evaluation, polar plot.

A circle of radius ``R`` in the plane xy, yz or zx of the workpiece frame, centred at the pose's
workpiece origin unless given, is written as a G-code program (a 90 deg lead-in arc, the full
circle, a 90 deg lead-out arc, all ``G3`` counter-clockwise about the plane normal or ``G2``),
interpolated jerk-limited at the 2 ms cycle (:mod:`simulate.toolpath.interpolation`), and run
through the machining pipeline (:func:`simulate.pipeline.run_job`: inverse kinematics, the coupled
loop with the same two-mass drives and friction models as ``machine``) without stock, so nothing is
cut (:func:`simulate_circle`, the one place the simulation is called). Only the full circle is
evaluated, so acceleration from and to rest is not in the trace.

Evaluation of the tool positions (forward kinematics of the simulated link positions), in the
circle's plane:

- **radial deviation** per sample ``F_i = |p_i - c_LS| - R`` about the least-squares centre
  ``c_LS`` (centring offsets removed as a ballbar evaluation does), outward positive;
- **roundness** ``max F - min F``, the circular deviation G of ISO 230-4 (smallest radial gap of
  two concentric circles about the least-squares centre that enclose the trace);
- **radius error** ``R_LS - R`` (the trace's least-squares radius minus the nominal one);
- **reversals**: where a joint's commanded velocity changes sign along the circle (on a robot
  these are the angles where glitches appear, not the Cartesian quadrants). Each reversal is
  split as a ballbar analysis splits it (Renishaw QC20-W ballbar system manual, diagnostics
  "backlash" and "reversal spikes"; ISO 230-4:2005 Annex; Knapp, Precision Engineering 5(2), 1983;
  Kakino et al., 1993; ``docs/drive-model.md``):

  * **settled trace before** ``L_b``: a least-squares line of ``F`` over the
    ``BEFORE_WINDOW_DEG`` before the reversal angle ``a_r`` (the trace is settled there unless
    another joint reversed just before);
  * **settled trace after** ``L_a``, fitted *together with the transient* (the link mode ringing
    after the flank impact outlasts any fixed window: A1's 7-8 Hz mode at a damping ratio of about
    0.08 decays by e in about 0.28 s, 11 deg at 2000 mm/min on R 50 mm, and starts only after the
    stick time): from the transient's start ``x0`` to the end of the fit span,
    ``F = L_a(x) + exp(-(x - x0) / (tau w)) (A cos + B sin)(2 pi f (x - x0) / w)`` with ``x`` the
    travelled angle from the reversal, ``w`` the circle's angular speed [deg/s], ``L_a`` the
    harmonic ``c0 + c1 sin x + c2 (1 - cos x)`` (exact for a constant in-plane lag, which projects
    onto the radial direction as a sinusoid of the angle; a line or quadratic extrapolated over tens
    of degrees is not), ``f`` in ``RING_HZ`` (2-20 Hz: the loop's slow poles at 4-5 Hz and the
    A1-A3 link modes at 5-14 Hz; faster wrist modes are over within a few degrees) and ``tau`` in
    ``RING_DECAY_S`` (0.02-1 s: from spikes that return within a degree to A1's mode at a damping
    ratio of 0.035 with twice its home inertia), ``f`` with at least ``MIN_RING_PERIODS`` (2)
    periods in the fit (a slower oscillation trades off against the harmonic); the amplitudes and
    ``c`` by linear least squares for each ``(f, tau)`` of a grid, the best refined (bounded
    quasi-Newton on the residual, variable projection). ``x0`` is where ``|F - L_b|`` is largest
    within ``TRANSIENT_SCAN_DEG`` (20 deg) after the reversal: the flank impact (the step's top or
    its overshoot), so the unmodelled play crossing before it is not fitted;
  * the **fit span** is ``FIT_SPAN_DEG`` (60 deg, 5 e-folding lengths of A1's ringing) after the
    reversal, cut at the next reversal (whose effect on the trace starts only after it); where less
    than ``MIN_RING_FIT_DEG`` is left after ``x0`` the oscillation cannot be told from the trace and
    ``L_a`` is a line over what is left;
  * **lost motion** ``s = L_a(x0) - L_b(x0)``: the step of the settled trace where the trace after
    starts (on a constant-lag trace the same as at the reversal; an extrapolation of ``L_a`` back
    to the reversal would amplify the misfit of the short fits a near neighbour leaves);
  * **reversal spike** ``h``: the extreme of ``F`` beyond the band of the settled traces over the
    fit span, beyond the upper edge positive, below the lower negative (0 for a clean step). The
    band is ``[L_b(x), L_a(x)]`` (ordered) up to ``x0`` and ``[L_a(x) - s, L_a(x)]`` after it (the
    before trace carried along the curved settled trace, as a line extrapolated far is not). A pure
    step gives ``h = 0``, a spike that returns to the trace ``s = 0``.

  The results converge with the fit span (on a synthetic step with ringing on a curved trace they
  change by less than 2 % between 40 and 80 deg, where the former fixed windows, a 15 deg spike
  window and a line over the 10 deg after it, moved the spike by more than 30 %; the shipped robot's
  figures are in ``docs/drive-model.md``). Its precision limit is the line before, whose curvature
  error where the fit starts is 1-3 µm on a 100 µm constant-lag curve. Reversals closer than
  ``SAME_REVERSAL_DEG`` count as one; otherwise the before window stops at the previous reversal.
  The trace is closed (a full circle), so a reversal near the start has its before window at the
  trace's end, and a joint reversing across the start is found too. The extreme of
  ``F - F(reversal)`` within ``SPIKE_WINDOW_DEG`` after it (``height_um``: lost motion and spike
  together) is kept as the reversal's *excursion*.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np

from identify.errors import InputError

#: Circle plane -> (G code, in-plane axes (first, second), normal axis); angle 0 along the first axis.
_PLANES = {"xy": (17, (0, 1), 2), "zx": (18, (2, 0), 1), "yz": (19, (1, 2), 0)}
#: Arc length of the lead-in and lead-out arcs [deg].
LEAD_DEG = 90.0
#: Window after a joint reversal for the lumped excursion ``height_um`` [deg of the circle].
SPIKE_WINDOW_DEG = 15.0
#: Window before a reversal where the settled trace before it is fitted [deg].
BEFORE_WINDOW_DEG = 10.0
#: Span after a reversal over which the settled trace and the transient are fitted [deg] (cut at the next one).
FIT_SPAN_DEG = 60.0
#: Window after a reversal in which the transient's start (largest |F - L_b|) is searched [deg].
TRANSIENT_SCAN_DEG = 20.0
#: Shortest fit after the transient's start for the oscillation to be fitted [deg]; shorter: a line.
MIN_RING_FIT_DEG = 15.0
#: Frequency band [Hz] and decay time range [s] of the transient's oscillation.
RING_HZ = (2.0, 20.0)
RING_DECAY_S = (0.02, 1.0)
#: Periods of the oscillation the fit must hold at least (slower ones are not told from the settled trace) [-].
MIN_RING_PERIODS = 2.0
#: Reversals closer than this along the circle count as one [deg].
SAME_REVERSAL_DEG = 0.5
#: A joint reverses only where its commanded speed exceeds this share of its peak on both sides [-] ...
REVERSAL_DEADBAND = 1e-3
#: ... and this absolute speed [rad/s] (a joint the circle does not move only shows round-off of the IK).
REVERSAL_MIN_SPEED = 1e-5


class Plane(str, Enum):
    """Plane of the circle in the workpiece frame (angle 0 along the first axis)."""

    XY = "xy"
    YZ = "yz"
    ZX = "zx"


@dataclass(frozen=True)
class CircleSpec:
    """The commanded circle.

    Attributes
    ----------
    radius : float
        m.
    feed : float
        Path speed, m/s.
    plane : Plane
    center : ndarray (3,)
        Centre in the workpiece frame, m.
    ccw : bool
        Counter-clockwise about the plane normal (G3), else clockwise (G2).
    """

    radius: float
    feed: float
    plane: Plane = Plane.XY
    center: tuple = (0.0, 0.0, 0.0)
    ccw: bool = True

    def __post_init__(self):
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"radius must be finite and > 0, got {self.radius * 1e3:g} mm", field="radius-mm")
        if not (math.isfinite(self.feed) and self.feed > 0):
            raise InputError(f"feed must be finite and > 0, got {self.feed * 6e4:g} mm/min", field="feed-mm-min")
        try:
            object.__setattr__(self, "plane", Plane(self.plane))
        except ValueError:
            raise InputError(f"unknown plane '{self.plane}' (known: xy, yz, zx)", field="plane") from None
        c = np.asarray(self.center, float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise InputError("centre must be three finite numbers x,y,z", field="center-mm")
        object.__setattr__(self, "center", tuple(float(v) for v in c))


def circle_gcode(spec: CircleSpec) -> str:
    """The circle as a G-code program (mm, G90): lead-in 90 deg, full circle, lead-out 90 deg."""
    g_plane, (a1, a2), _ = _PLANES[spec.plane.value]
    c = np.array(spec.center) * 1e3
    R = spec.radius * 1e3
    sgn = 1.0 if spec.ccw else -1.0
    letters = "XYZ"
    centre_words = "IJK"

    def point(angle_deg):
        p = c.copy()
        p[a1] += R * math.cos(math.radians(angle_deg))
        p[a2] += R * math.sin(math.radians(angle_deg))
        return p

    def words(p):
        return " ".join(f"{letters[i]}{p[i]:.6f}" for i in range(3))

    def arc(p_from, p_to):
        off = c - p_from
        return (f"{'G3' if spec.ccw else 'G2'} {words(p_to)} "
                f"{centre_words[a1]}{off[a1]:.6f} {centre_words[a2]}{off[a2]:.6f}")

    p0, p1 = point(0.0), point(sgn * LEAD_DEG)
    lines = [f"(virtual circular test: R {R:g} mm, F {spec.feed * 6e4:g} mm/min, plane {spec.plane.value})",
             f"G21 G90 G94 G{g_plane}", f"G0 {words(p0)}", f"G1 {words(p0)} F{spec.feed * 6e4:.6f}",
             arc(p0, p1), arc(p1, p1), arc(p1, point(2 * sgn * LEAD_DEG))]
    return "\n".join(lines + ["M30"]) + "\n"


def circle_program(spec: CircleSpec):
    """The parsed program, starting at rest on the circle (the positioning move dropped)."""
    from simulate.toolpath.gcode import Arc, Linear, parse_program

    prog = parse_program(circle_gcode(spec), source="<circle>")
    arcs: list[Linear | Arc] = [s for s in prog.segments if isinstance(s, Arc)]
    return dataclasses.replace(prog, segments=arcs, start=arcs[0].start.copy())


@dataclass(frozen=True, eq=False)
class CircleRun:
    """Commanded and simulated motion along the circle program (all samples, 2 ms).

    Attributes
    ----------
    t : ndarray (M,)
        s.
    segment : ndarray (M,) of int
        0 lead-in, 1 the evaluated full circle, 2 lead-out.
    xyz_cmd, xyz : ndarray (M, 3)
        Commanded and simulated TCP in the workpiece frame, m.
    q_cmd, q : ndarray (M, 6)
        Commanded and simulated link positions, rad.
    contact : ndarray (M, 6) of int8
        Gear flank per sample (:class:`simulate.robot.drive.Contact`).
    friction : list of dict
        Per joint the friction model used (``{"joint", "kind", "source"}``).
    spec : CircleSpec
    """

    t: np.ndarray
    segment: np.ndarray
    xyz_cmd: np.ndarray
    xyz: np.ndarray
    q_cmd: np.ndarray
    q: np.ndarray
    contact: np.ndarray
    friction: list
    spec: CircleSpec


def circle_job(robot, placement, spec: CircleSpec, *, friction: bool = True, backlash: bool = True,
               friction_scale: float = 1.0, ff_friction: bool = False, friction_models: dict | None = None,
               limits=None):
    """The circle as a machining job without stock, prepared (interpolation, inverse kinematics).

    Returns ``(job, prepared)`` for :func:`simulate.pipeline.run_job`. ``friction_models``: joint
    1..6 -> model reference replacing the robot file's (as a machining job's ``friction``).

    Raises
    ------
    InputError
        The circle leaves the robot's reach or joint limits at this pose (``field="radius-mm"``),
        or a bad friction scale (``friction-scale``).
    """
    from simulate import defaults
    from simulate.pipeline import Components, MachiningJob, MachiningSettings, ProgramSetup, prepare
    from simulate.toolpath.interpolation import interpolate

    prog = circle_program(spec)
    ip = interpolate(prog, limits)
    setup = ProgramSetup(program=Path("<circle>"), source="<circle>", parsed=prog, interp=ip, stock=None,
                         stock_doc={}, spindle_rpm=defaults.SPINDLE_RPM)
    job = MachiningJob(program=setup, robot=robot, placement=placement, friction=dict(friction_models or {}),
                       components=Components(deflection=False, friction=friction, switching=backlash, servo=True),
                       settings=MachiningSettings(size=0, friction_scale=friction_scale, ff_friction=ff_friction))
    job.settings.validate()
    try:
        return job, prepare(job)
    except InputError as exc:
        raise InputError(f"the circle (R {spec.radius * 1e3:g} mm, plane {spec.plane.value}) is not feasible at "
                         f"pose '{placement.name}': {exc.message}", field="radius-mm") from None


def simulate_circle(robot, placement, spec: CircleSpec, *, friction: bool = True, backlash: bool = True,
                    friction_scale: float = 1.0, ff_friction: bool = False, friction_models: dict | None = None,
                    limits=None, advance=None) -> CircleRun:
    """Simulate the circle through the machining pipeline without stock (module docstring).

    The drives get the load from the simulated state every cycle (gravity, inertial coupling; no
    process force, nothing is cut) and each joint's friction model of the robot file, or of
    ``friction_models`` (joint 1..6 -> model reference, as a machining job's ``friction``).
    ``friction_scale`` multiplies every joint's Coulomb and static levels [-]; ``ff_friction``
    switches the NC's friction feed-forward on; ``advance(n)`` gets the loop's progress in steps.

    Raises
    ------
    InputError
        As :func:`circle_job`; a bad friction model reference (naming the robot file key or the job
        field).
    """
    from simulate.pipeline import run_job
    from simulate.robot.kinematics import fk

    job, pj = circle_job(robot, placement, spec, friction=friction, backlash=backlash, friction_scale=friction_scale,
                         ff_friction=ff_friction, friction_models=friction_models, limits=limits)
    out = run_job(job, prepared=pj, advance=advance)
    jt, res = out.trajectory, out.result
    assert res.joint_contact is not None  # the drives run in every circle, so every step has its flank
    q = jt.q - res.joint_error
    T_wb = np.linalg.inv(placement.T)
    p_base = fk(out.robot, q)[:, :3, 3]
    xyz = p_base @ T_wb[:3, :3].T + T_wb[:3, 3]
    return CircleRun(t=jt.t, segment=np.asarray(out.program.interp.segment), xyz_cmd=np.asarray(out.program.interp.xyz),
                     xyz=xyz, q_cmd=jt.q, q=q, contact=res.joint_contact, friction=out.friction, spec=spec)


# --------------------------------------------------------------------------- evaluation

@dataclass(frozen=True)
class ReversalSpike:
    """A glitch where one joint reverses.

    Attributes
    ----------
    angle_deg : float
        Circle angle of the joint's velocity reversal [deg], 0 along the plane's first axis.
    joint : int
        The reversing joint, 1..6 (A1..A6).
    height_um : float
        Excursion: extreme of the radial deviation relative to its value at the reversal, within
        ``SPIKE_WINDOW_DEG`` after it [µm], outward positive (lost motion and spike together).
    peak_angle_deg : float
        Angle of that extreme [deg].
    spike_um : float
        Reversal spike: the transient peak beyond the settled trace before and after the
        reversal [µm], outward positive (module docstring).
    lost_motion_um : float
        Lost motion: step of the settled trace across the reversal, after minus before [µm].
    spike_angle_deg : float
        Angle of the spike's peak [deg] (default ``peak_angle_deg``).
    """

    angle_deg: float
    joint: int
    height_um: float
    peak_angle_deg: float
    spike_um: float = 0.0
    lost_motion_um: float = 0.0
    spike_angle_deg: float | None = None

    def __post_init__(self):
        if self.spike_angle_deg is None:
            object.__setattr__(self, "spike_angle_deg", self.peak_angle_deg)

    @property
    def name(self) -> str:
        return f"A{self.joint}"


@dataclass(frozen=True, eq=False)
class CircleResult:
    """Evaluation of one circle trace.

    Attributes
    ----------
    angle_deg : ndarray (N,)
        Angle of each evaluated sample about the least-squares centre [deg], 0..360, in path order.
    deviation_um : ndarray (N,)
        Radial deviation ``|p - c_LS| - R`` [µm], outward positive.
    q : ndarray (N, 6)
        Simulated link positions [rad] of the samples.
    roundness_um : float
        Circular deviation G (ISO 230-4) [µm].
    radius_error_um : float
        Least-squares radius minus nominal [µm].
    center_offset_um : ndarray (2,)
        Least-squares centre minus nominal centre, in-plane axes [µm].
    spikes : tuple of ReversalSpike
    radius_m, feed_m_s : float
        Nominal radius [m] and feed [m/s].
    plane : str
    """

    angle_deg: np.ndarray
    deviation_um: np.ndarray
    q: np.ndarray
    roundness_um: float
    radius_error_um: float
    center_offset_um: np.ndarray
    spikes: tuple
    radius_m: float
    feed_m_s: float
    plane: str

    @property
    def largest_excursion_um(self) -> float:
        """Largest |excursion| ``height_um`` at a reversal [µm] (lost motion and spike together; 0
        when no joint reverses)."""
        return max((abs(s.height_um) for s in self.spikes), default=0.0)

    @property
    def largest_spike_um(self) -> float:
        """Deprecated alias of :attr:`largest_excursion_um` [µm], kept for compatibility (the JSON key
        too): despite the name it is the lumped excursion, not the ballbar reversal spike
        (:attr:`largest_reversal_spike_um`)."""
        return self.largest_excursion_um

    @property
    def largest_reversal_spike_um(self) -> float:
        """Largest |spike| beyond the settled trace, ``spike_um`` [µm] (ballbar reversal spike)."""
        return max((abs(s.spike_um) for s in self.spikes), default=0.0)

    @property
    def largest_lost_motion_um(self) -> float:
        """Largest |lost motion| step at a reversal, ``lost_motion_um`` [µm] (ballbar backlash)."""
        return max((abs(s.lost_motion_um) for s in self.spikes), default=0.0)

    def summary(self) -> dict:
        """Plain numbers for printing / JSON."""
        return {"roundness_um": self.roundness_um, "radius_error_um": self.radius_error_um,
                "center_offset_um": [float(v) for v in self.center_offset_um],
                "largest_excursion_um": self.largest_excursion_um,
                "largest_spike_um": self.largest_excursion_um,   # deprecated alias of largest_excursion_um
                "largest_reversal_spike_um": self.largest_reversal_spike_um,
                "largest_lost_motion_um": self.largest_lost_motion_um,
                "reversal_spikes": [{"angle_deg": s.angle_deg, "joint": s.name, "height_um": s.height_um,
                                     "spike_um": s.spike_um, "lost_motion_um": s.lost_motion_um}
                                    for s in self.spikes]}


def joint_reversals(qd: np.ndarray, deadband: float = REVERSAL_DEADBAND,
                    min_speed: float = REVERSAL_MIN_SPEED, *, closed: bool = False) -> list[tuple[int, int]]:
    """``(sample, joint)`` where a joint velocity [rad/s] changes sign (joint 0-based).

    Speeds below ``deadband`` times the joint's peak speed, or below ``min_speed`` [rad/s], count
    as no sign; a reversal is the first sample of the new sign (a joint that does not move has none).
    ``closed``: the samples are one turn of a periodic motion (a full circle), so a sign change from
    the last sample to the first is a reversal too (at the first signed sample).
    """
    qd = np.asarray(qd, float)
    out = []
    for j in range(qd.shape[1]):
        v = qd[:, j]
        peak = np.abs(v).max() if len(v) else 0.0
        if not peak > 0:
            continue
        s = np.where(np.abs(v) > max(deadband * peak, min_speed), np.sign(v), 0.0)
        signed = s[s != 0.0]
        last = float(signed[-1]) if closed and signed.size else 0.0
        for k in range(len(s)):
            if s[k] == 0.0:
                continue
            if last != 0.0 and s[k] != last:
                out.append((k, j))
            last = s[k]
    return sorted(out)


@dataclass(frozen=True)
class ReversalSplit:
    """A reversal split into lost motion and spike (:func:`split_reversal`; units of the trace).

    Attributes
    ----------
    lost_motion : float
        Step of the settled trace, after minus before, at the reversal angle.
    spike : float
        Peak beyond the band between the settled traces before and after, signed (0 inside it).
    index : int
        Sample of the spike's peak (of the trace passed in).
    ring_hz : float
        Frequency of the fitted transient's oscillation [Hz] (nan where the span was too short).
    ring_decay_s : float
        Its decay time [s] (nan where the span was too short).
    fit_start_deg, fit_end_deg : float
        Travelled angle from the reversal where the settled trace after it was fitted [deg].
    """

    lost_motion: float
    spike: float
    index: int
    ring_hz: float = math.nan
    ring_decay_s: float = math.nan
    fit_start_deg: float = math.nan
    fit_end_deg: float = math.nan


def _harmonic(x_deg: np.ndarray) -> np.ndarray:
    """Columns ``1, sin x, 1 - cos x`` of the settled trace (value ``c0`` at ``x = 0``)."""
    r = np.radians(x_deg)
    return np.stack([np.ones_like(r), np.sin(r), 1.0 - np.cos(r)], 1)


def _fit_settled_and_ring(x: np.ndarray, y: np.ndarray, deg_per_s: float) -> tuple[np.ndarray, float, float]:
    """Least squares of ``y(x) = harmonic + exp(-x / (tau w)) (A cos + B sin)(2 pi f x / w)`` (``x`` from
    the transient's start [deg], ``w = deg_per_s``): the harmonic's coefficients, ``f`` [Hz], ``tau`` [s].

    Variable projection: for fixed ``(f, tau)`` the rest is linear, so the residual of the oscillation
    against ``y`` with the harmonic projected out is minimised over a grid of ``f`` (0.25 Hz) and
    ``tau`` (11 log-spaced) in ``RING_HZ`` x ``RING_DECAY_S``, the best point then refined within them;
    frequencies with fewer than ``MIN_RING_PERIODS`` periods in the fit are left out (over a short fit
    a slow, slowly decaying oscillation and the harmonic trade off, and the settled trace's value at
    the reversal, an extrapolation, would be arbitrary)."""
    from scipy.optimize import minimize

    h = _harmonic(x)
    qh, _ = np.linalg.qr(h)
    yp = y - qh @ (qh.T @ y)

    def residual(hz: np.ndarray, tau: np.ndarray) -> np.ndarray:
        om = 2.0 * np.pi * hz[:, None] / deg_per_s
        env = np.exp(-x[None, :] / (tau[:, None] * deg_per_s))
        c = np.stack([env * np.cos(om * x), env * np.sin(om * x)], 2)             # (k, n, 2)
        c = c - qh @ (qh.T @ c)
        g = np.swapaxes(c, 1, 2) @ c + 1e-12 * np.eye(2)
        b = yp @ c
        return yp @ yp - np.einsum("ki,ki->k", b, np.linalg.solve(g, b[..., None])[..., 0])

    # an oscillation with fewer than MIN_RING_PERIODS in the fit trades off against the harmonic
    f_lo = min(RING_HZ[1], max(RING_HZ[0], MIN_RING_PERIODS * deg_per_s / max(float(x[-1]), 1e-9)))
    hz_grid, tau_grid = np.meshgrid(np.linspace(f_lo, RING_HZ[1], 1 + round((RING_HZ[1] - f_lo) / 0.25)),
                                    np.geomspace(RING_DECAY_S[0], RING_DECAY_S[1], 11))
    r = residual(hz_grid.ravel(), tau_grid.ravel())
    i = int(np.argmin(r))
    lo, hi = math.log(RING_DECAY_S[0]), math.log(RING_DECAY_S[1])
    best = minimize(lambda p: float(residual(np.array([p[0]]), np.array([math.exp(p[1])]))[0]),
                    [hz_grid.ravel()[i], math.log(tau_grid.ravel()[i])], method="L-BFGS-B",
                    bounds=[(f_lo, RING_HZ[1]), (lo, hi)])
    hz, tau = float(best.x[0]), math.exp(float(best.x[1]))
    om, env = 2.0 * np.pi * hz / deg_per_s, np.exp(-x / (tau * deg_per_s))
    a = np.column_stack([h, env * np.cos(om * x), env * np.sin(om * x)])
    return np.linalg.lstsq(a, y, rcond=None)[0][:3], hz, tau


def split_reversal(trav_deg, dev, at_deg: float, *, deg_per_s: float, neighbours=(),
                   span_deg: float = FIT_SPAN_DEG, before_deg: float = BEFORE_WINDOW_DEG) -> ReversalSplit:
    """Lost motion and spike of a closed trace at one reversal, the transient modelled (module docstring).

    Parameters
    ----------
    trav_deg : array_like (N,)
        Travelled angle of each sample [deg], increasing, within one turn (``0 <= trav < 360``).
    dev : array_like (N,)
        Radial deviation (any unit; the results are in the same unit).
    at_deg : float
        Travelled angle of the reversal [deg].
    deg_per_s : float
        Angular speed along the circle [deg/s] (feed over radius): converts the oscillation's
        frequency and decay time into travelled angle.
    neighbours : array_like
        Travelled angles of all reversals [deg]: the before window and the fit span stop at the
        previous and next ones (those closer than ``SAME_REVERSAL_DEG`` count as this one).
    span_deg, before_deg : float
        Fit span after the reversal, window before it [deg].
    """
    t = np.asarray(trav_deg, float)
    d = np.asarray(dev, float)
    n = t.size
    # the trace is closed: one turn either side gives every window its samples
    te = np.concatenate([t - 360.0, t, t + 360.0])
    de = np.concatenate([d, d, d])
    gaps = (np.asarray(neighbours, float) % 360.0 - at_deg) % 360.0
    gaps = gaps[(gaps > SAME_REVERSAL_DEG) & (gaps < 360.0 - SAME_REVERSAL_DEG)]
    ahead = float(gaps.min()) if gaps.size else 360.0
    behind = float((360.0 - gaps).min()) if gaps.size else 360.0

    sel = (te >= at_deg - min(before_deg, behind)) & (te < at_deg)
    if np.count_nonzero(sel) >= 2:
        lb = np.poly1d(np.polyfit(te[sel] - at_deg, de[sel], 1))
    else:
        lb = np.poly1d([float(de[np.argmin(np.abs(te - at_deg))])])
    end = min(span_deg, ahead)
    idx = np.nonzero((te >= at_deg) & (te < at_deg + end))[0]
    if idx.size < 2:
        k = int(np.argmin(np.abs(te - at_deg)))
        return ReversalSplit(lost_motion=0.0, spike=0.0, index=k % n)
    x, y = te[idx] - at_deg, de[idx]
    scan = np.nonzero(x < min(TRANSIENT_SCAN_DEG, end))[0]
    k0 = int(scan[np.argmax(np.abs(y[scan] - lb(x[scan])))])
    x0, xf, yf = float(x[k0]), x[k0:], y[k0:]
    hz = tau = math.nan
    if xf[-1] - x0 >= MIN_RING_FIT_DEG:
        coef, hz, tau = _fit_settled_and_ring(xf - x0, yf, deg_per_s)
        # the harmonic in x - x0 re-expressed as one in x: same span {1, sin x, cos x}
        c0, c1, c2 = coef
        r0 = math.radians(x0)

        def la(xx):
            return c0 + c2 + c1 * np.sin(np.radians(xx) - r0) - c2 * np.cos(np.radians(xx) - r0)
    else:   # too short for the oscillation: a line over what is left (a constant from one sample)
        la = np.poly1d(np.polyfit(xf, yf, 1) if xf.size >= 2 else [float(yf[0])])
    la_x = np.asarray(la(x), float)
    # the step where the settled trace after starts (an extrapolation back to the reversal angle
    # amplifies any misfit of the short fits a near neighbour leaves)
    s = float(la(x0) - lb(x0))
    other = np.where(x <= x0, lb(x), la_x - s)
    hi, lo = np.maximum(la_x, other), np.minimum(la_x, other)
    excess = np.where(y > hi, y - hi, np.where(y < lo, y - lo, 0.0))
    m = int(np.argmax(np.abs(excess)))
    return ReversalSplit(lost_motion=s, spike=float(excess[m]), index=int(idx[m] % n), ring_hz=hz,
                         ring_decay_s=tau, fit_start_deg=x0, fit_end_deg=float(x[-1]))


def evaluate_circle(xyz, q, qd_cmd, spec: CircleSpec, *, window_deg: float = SPIKE_WINDOW_DEG) -> CircleResult:
    """Evaluate one trace of the full circle.

    Parameters
    ----------
    xyz : array_like (N, 3)
        Tool positions in the workpiece frame [m], in path order.
    q : array_like (N, 6)
        Link positions [rad] (for the CSV).
    qd_cmd : array_like (N, 6)
        Commanded joint velocities [rad/s] (where they change sign, joints reverse).
    spec : CircleSpec
    window_deg : float
        Window after a reversal for the lumped excursion ``height_um`` [deg].
    """
    from simulate.evaluation.fits import fit_circle_ls

    _, (a1, a2), _ = _PLANES[spec.plane.value]
    p = np.asarray(xyz, float)[:, [a1, a2]]
    fit = fit_circle_ls(p)
    d = np.hypot(p[:, 0] - fit.center[0], p[:, 1] - fit.center[1])
    dev = (d - spec.radius) * 1e6
    ang = np.degrees(np.arctan2(p[:, 1] - fit.center[1], p[:, 0] - fit.center[0])) % 360.0
    # travelled angle along the path (unwrapped, increasing) for the split and the excursion window
    trav = np.degrees(np.abs(np.unwrap(np.radians(ang)) - math.radians(ang[0])))
    spikes = []
    reversals = joint_reversals(qd_cmd, closed=True)
    at = np.unique([trav[k] for k, _ in reversals])
    deg_per_s = math.degrees(spec.feed / spec.radius)
    splits: dict[float, ReversalSplit] = {}
    for k, j in reversals:
        sel = np.nonzero((trav >= trav[k]) & (trav <= trav[k] + window_deg))[0]
        rel = dev[sel] - dev[k]
        m = int(np.argmax(np.abs(rel)))
        if trav[k] not in splits:    # joints reversing at the same sample share one split
            splits[trav[k]] = split_reversal(trav, dev, trav[k], deg_per_s=deg_per_s, neighbours=at)
        split = splits[trav[k]]
        spikes.append(ReversalSpike(angle_deg=float(ang[k]), joint=j + 1, height_um=float(rel[m]),
                                    peak_angle_deg=float(ang[sel[m]]), spike_um=split.spike,
                                    lost_motion_um=split.lost_motion, spike_angle_deg=float(ang[split.index])))
    c_nom = np.array(spec.center)[[a1, a2]]
    return CircleResult(angle_deg=ang, deviation_um=dev, q=np.asarray(q, float),
                        roundness_um=float(dev.max() - dev.min()),
                        radius_error_um=float((fit.radius - spec.radius) * 1e6),
                        center_offset_um=(fit.center - c_nom) * 1e6, spikes=tuple(spikes), radius_m=spec.radius,
                        feed_m_s=spec.feed, plane=spec.plane.value)


def evaluate_run(run: CircleRun) -> CircleResult:
    """Evaluate the full-circle part of a :class:`CircleRun`."""
    from simulate.robot.drive import command_velocity

    sel = run.segment == 1
    qd = command_velocity(run.t, run.q_cmd)
    return evaluate_circle(run.xyz[sel], run.q[sel], qd[sel], run.spec)


# --------------------------------------------------------------------------- outputs

def circle_table(result: CircleResult):
    """The CSV table: angle [deg], radial deviation [µm], link positions q1..q6 [rad]."""
    import pandas as pd

    df = pd.DataFrame({"angle_deg": result.angle_deg, "radial_deviation_um": result.deviation_um})
    for j in range(6):
        df[f"q{j + 1}_rad"] = result.q[:, j]
    return df


def polar_plot(result: CircleResult, path: str | Path, title: str = "") -> str:
    """A ballbar-style polar plot: radial deviation magnified about the nominal circle, spikes marked.

    The radial axis is the deviation in µm (the nominal circle is the dashed 0 µm ring), so the
    trace's shape is magnified by the ratio of the radius to the plotted deviation range.
    """
    from simulate.evaluation.report import _plt, _save

    plt = _plt()
    dev = result.deviation_um
    lo, hi = float(min(dev.min(), 0.0)), float(max(dev.max(), 0.0))
    span = max(hi - lo, 1e-3)
    lo, hi = lo - 0.15 * span, hi + 0.15 * span
    fig = plt.figure(figsize=(7.5, 7.5))
    ax = fig.add_subplot(projection="polar")
    ax.set_rorigin(lo - 1.2 * (hi - lo))
    ax.set_ylim(lo, hi)
    th = np.radians(result.angle_deg)
    ax.plot(np.linspace(0, 2 * np.pi, 361), np.zeros(361), "--", color="0.5", lw=1, label="nominal (0 µm)")
    ax.plot(th, dev, color="tab:blue", lw=1.2, label="radial deviation")
    colours = plt.get_cmap("tab10")

    def nearest(angle):
        return int(np.argmin(np.abs((result.angle_deg - angle + 180.0) % 360.0 - 180.0)))

    # joints reversing at the same sample share one spike: one mark, one label naming them all
    groups: dict[tuple, list] = {}
    for s in result.spikes:
        groups.setdefault((round(s.angle_deg, 6), round(s.peak_angle_deg, 6)), []).append(s)
    for (a_rev, _), group in groups.items():
        colour = colours(group[0].joint - 1)
        k, kr = nearest(group[0].spike_angle_deg), nearest(a_rev)
        ax.plot([th[kr]], [dev[kr]], marker="|", ms=14, mew=2, color=colour)
        ax.plot([th[k]], [dev[k]], marker="o", ms=6, color=colour)
        ax.annotate(f"{'+'.join(s.name for s in group)} spike {group[0].spike_um:+.1f} µm, "
                    f"lost motion {group[0].lost_motion_um:+.1f} µm", (th[k], dev[k]),
                    textcoords="offset points", xytext=(6, 6), fontsize=8, color=colour)
    ax.set_rlabel_position(22.5)
    ax.set_ylabel("radial deviation [µm]", labelpad=28)
    ax.set_title(title + ("\n" if title else "") +
                 f"R {result.radius_m * 1e3:g} mm, F {result.feed_m_s * 6e4:g} mm/min, plane {result.plane}: "
                 f"roundness {result.roundness_um:.1f} µm, radius error {result.radius_error_um:+.1f} µm", fontsize=10)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.1, -0.12), fontsize=8)
    fig.text(0.98, 0.02, "| joint reversal, o spike peak; label: joint, spike beyond the settled trace,\n"
             "lost motion (step of the settled trace across the reversal) [µm]", ha="right", fontsize=8)
    return _save(fig, Path(path))


def write_outputs(result: CircleResult, out_dir: str | Path, *, title: str = "", info: dict | None = None) -> dict:
    """Write ``circle.csv`` (:func:`circle_table`), ``circle.png`` (:func:`polar_plot`) and
    ``summary.json`` into ``out_dir``; returns the summary (``info`` + :meth:`CircleResult.summary` +
    the file paths). Everything is computed before this is called: only writing happens here."""
    import json

    from identify.records import write_table

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    csv = write_table(circle_table(result), out_dir / "circle.csv")
    png = out_dir / polar_plot(result, out_dir / "circle.png", title)
    summary = {**(info or {}), **result.summary(), "csv": str(csv), "png": str(png)}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
    return summary
