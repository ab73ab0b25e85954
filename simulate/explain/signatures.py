"""Signatures of a discrepancy field, ballbar style: what its shape looks like, in numbers.

Computed on a per-point field ``r`` (measured - simulated deviation, or a cause's fitted contribution)
at the compared probe points (:class:`simulate.explain.comparison.PointComparison`):

- **size error** [m]: mean of ``r`` over the side walls (the circle's diameter changes by twice it);
- **ovality** [m] and its **direction** [deg]: order-2 Fourier amplitude of ``r`` around the circle wall
  (peak value of ``a cos 2(phi - phi0)``) and ``phi0`` (workpiece frame, from +x);
- **lobing** [m]: the largest Fourier amplitude of orders 3..15 and its order;
- **trend** [m/s]: slope of ``r`` against the time its surface was cut (least squares over all points)
  and the change over the cut;
- **height offset** [m]: mean of ``r`` over floors, tops and the slope (normals along z);
- **reversal steps** [m] per axis: mean |mean after - mean before| of ``r`` over the points cut within
  0.5 s on either side of the axis's switching points (paper 3.7), excluding 20 ms around them;
- **reversal spikes** [m] per axis: largest |r - median| within 50 ms of an axis switching point.

These describe; the cause is chosen by :mod:`simulate.explain.causes`, which compares whole fields.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Signatures:
    size: float = 0.0
    ovality: float = 0.0
    ovality_direction: float = 0.0
    lobing: float = 0.0
    lobing_order: int = 0
    trend: float = 0.0
    trend_change: float = 0.0
    height_offset: float = 0.0
    reversal_step: dict[int, float] = field(default_factory=dict)
    reversal_spike: dict[int, float] = field(default_factory=dict)

    def rows(self) -> list[tuple[str, str]]:
        """(name, value text in um / deg) for tables."""
        um = 1e6
        out = [("size error [µm]", f"{self.size * um:+.2f}"),
               ("ovality [µm] @ direction [deg]", f"{self.ovality * um:.2f} @ {self.ovality_direction:.0f}"),
               ("lobing [µm] (order)", f"{self.lobing * um:.2f} ({self.lobing_order})"),
               ("trend [um/s] (change over cut [µm])", f"{self.trend * um:+.3f} ({self.trend_change * um:+.2f})"),
               ("height offset [µm]", f"{self.height_offset * um:+.2f}")]
        if self.reversal_step:
            out.append(("steps at reversals [µm], by axis",
                        ", ".join(f"A{a} {v * um:.2f}" for a, v in self.reversal_step.items())))
            out.append(("spikes at reversals [µm], by axis",
                        ", ".join(f"A{a} {v * um:.2f}" for a, v in self.reversal_spike.items())))
        return out


def circle_harmonics(phi: np.ndarray, r: np.ndarray, orders: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares Fourier amplitudes (orders 0..orders) of r(phi), order 0 the mean (units of ``r``),
    and the fitted coefficients ``(c0, a1, b1, a2, b2, ...)`` of ``c0 + sum a_k cos k phi + b_k sin k phi``."""
    cols = [np.ones_like(phi)]
    for k in range(1, orders + 1):
        cols += [np.cos(k * phi), np.sin(k * phi)]
    A = np.column_stack(cols)
    c, *_ = np.linalg.lstsq(A, r, rcond=None)
    amp = np.zeros(orders + 1)
    amp[0] = c[0]
    for k in range(1, orders + 1):
        amp[k] = math.hypot(c[2 * k - 1], c[2 * k])
    return amp, c


def signatures(cmp, r: np.ndarray, switch: np.ndarray | None = None, t_steps: np.ndarray | None = None,
               piece=None) -> Signatures:
    """Signatures of ``r`` (module docstring)."""
    r = np.asarray(r, float)
    s = Signatures()
    n = cmp.normals
    wall = np.abs(n[:, 2]) < 0.5
    if wall.any():
        s.size = float(np.mean(r[wall]))
    flat = ~wall
    if flat.any():
        s.height_offset = float(np.mean(r[flat]))
    circ = cmp.feature == "circle_wall"
    if circ.sum() >= 40:
        c = np.asarray(piece.circle_center if piece is not None else (0.0, 0.0), float)
        phi = np.arctan2(cmp.points[circ, 1] - c[1], cmp.points[circ, 0] - c[0])
        amp, coef = circle_harmonics(phi, r[circ], 15)
        s.ovality = float(amp[2])
        s.ovality_direction = float(math.degrees(0.5 * math.atan2(coef[4], coef[3])) % 180.0)
        k = int(np.argmax(amp[3:])) + 3
        s.lobing, s.lobing_order = float(amp[k]), k
    t = cmp.t
    ok = np.isfinite(t)
    if ok.sum() > 2 and np.ptp(t[ok]) > 0:
        A = np.column_stack([np.ones(ok.sum()), t[ok]])
        c, *_ = np.linalg.lstsq(A, r[ok], rcond=None)
        s.trend = float(c[1])
        s.trend_change = float(c[1] * np.ptp(t[ok]))
    if switch is not None and t_steps is not None and ok.any():
        sw = np.asarray(switch)
        for a in range(6):
            ev = np.asarray(t_steps)[(sw >> a) & 1 == 1]
            if len(ev) == 0:
                continue
            steps, spikes = [], [0.0]
            tt, rr = t[ok], r[ok]
            for te in ev:
                before = (tt > te - 0.5) & (tt < te - 0.02)
                after = (tt > te + 0.02) & (tt < te + 0.5)
                if before.sum() >= 3 and after.sum() >= 3:
                    steps.append(abs(np.mean(rr[after]) - np.mean(rr[before])))
                near = np.abs(tt - te) < 0.05
                if near.any():
                    base = np.median(rr[(np.abs(tt - te) < 0.5)])
                    spikes.append(float(np.max(np.abs(rr[near] - base))))
            if steps or len(spikes) > 1:
                s.reversal_step[a + 1] = float(np.mean(steps)) if steps else 0.0
                s.reversal_spike[a + 1] = float(max(spikes))
    return s
