"""Settings of the compensation and the contract of a correction (SI).

What a correction may be (:data:`MAX_OFFSET`, :data:`TIME_RATIO`), the grid it lives on (:data:`GRID`)
and how the iteration runs and writes the program (:class:`CompensationSettings`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from identify.errors import InputError

#: Grid of the correction along the nominal path [m].
GRID = 1e-4
#: The contract of a correction (not another program).
MAX_OFFSET = 1e-3          # m from the nominal path
TIME_RATIO = (0.8, 1.25)   # compensated / nominal program time [-]


@dataclass(frozen=True)
class CompensationSettings:
    """How the compensation iterates and writes the corrected program (SI).

    Attributes
    ----------
    iterations : int
        Largest number of corrected programs simulated [-].
    gain : float
        Damping of the update (1: full mirror / secant step) [-], in (0, 1.5].
    secant : bool
        Use the measured sensitivity from the second iteration on (:mod:`simulate.compensation.update`).
    smoothing : float
        Box window of the deviation along the path [m], applied twice (a triangular kernel of twice
        the width): the tool (10 mm) averages shorter detail, and coarse dexel grids make the force,
        hence the deflection, ripple at the dexel spacing.
    sensitivity_window : float
        Window of the sensitivity estimate along the path [m].
    fit_tolerance : float
        Largest distance of the written pieces from the corrected samples [m].
    max_piece : float
        Longest piece a line or arc is split into [m].
    min_piece : float
        Shortest piece [m] (a line is not split below twice this).
    max_correction : float
        Cap on the correction's magnitude [m]: the contract's 1 mm less a margin for the written pieces.
        On iso160 the square's and the circle's walls need up to 0.87-0.89 mm (the deflection grows with
        the deeper cut); at 0.5 mm the side length stayed 117-131 µm over size (``docs/compensation.md``).
    ramp : float
        Shortest piece [m] within this distance of where the original program changes speed
        (:func:`simulate.compensation.program.plan_pieces`).
    blend : bool
        Write ``G64`` (continuous-path blending, :mod:`simulate.toolpath.interpolation`) into the
        corrected program, before its first feed move, and keep every junction of the corrected pieces
        blendable at the programmed feed (:func:`simulate.compensation.program.junction_limit`,
        :func:`simulate.compensation.update.curvature_limit`): the dense pieces then carry speed and
        acceleration across their junctions and the program keeps its feed, as an NC's compressor /
        look-ahead switched on by the program does. Off: the pieces run under the default ``G61`` (zero
        acceleration at every junction).
    floor_envelope : bool
        Correct the lower envelope of the tip's height over the tool radius along the path instead of
        its mean (:mod:`simulate.compensation.measure`, *Floors*): the end face cuts a floor to the
        tip's lowest passes. Needs the tool radius (:func:`simulate.compensation.iterate.compensate`).
    keep_speed : bool
        Smooth the correction further where the written program would run slower than the original
        (:func:`simulate.compensation.update.keep_speed`); off (default): only the time contract lowers the
        curvature share. On iso160 (before ``blend``) it kept the feed (time 1.01-1.04x instead of
        1.21-1.24x) but lost more correction than it gained (near: sum ratio 0.58 instead of 0.31;
        ``docs/compensation.md``).
    """

    iterations: int = 6
    gain: float = 1.0
    secant: bool = True
    smoothing: float = 2e-3
    sensitivity_window: float = 10e-3
    fit_tolerance: float = 0.5e-6
    max_piece: float = 20e-3
    min_piece: float = 0.25e-3
    max_correction: float = 0.9e-3
    ramp: float = 1e-3
    blend: bool = True
    floor_envelope: bool = True
    keep_speed: bool = False

    def validate(self) -> None:
        """Raise ``InputError`` naming the setting (as the CLI option) that is out of range."""
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or not 1 <= self.iterations <= 20:
            raise InputError(f"must be an integer in 1..20, got {self.iterations!r}", field="iterations")
        if not (math.isfinite(self.gain) and 0 < self.gain <= 1.5):
            raise InputError(f"must be in (0, 1.5], got {self.gain!r}", field="gain")
        for name in ("smoothing", "sensitivity_window", "fit_tolerance", "max_piece", "min_piece", "max_correction",
                     "ramp"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v!r}", field=name.replace("_", "-"))
        if self.max_correction >= MAX_OFFSET:
            raise InputError(f"must stay below {MAX_OFFSET * 1e3:g} mm, got {self.max_correction * 1e3:g} mm",
                             field="max-correction")
