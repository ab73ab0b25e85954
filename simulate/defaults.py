"""The machining pipeline's defaults, in one place (SI units).

Every caller of the machining pipeline (:mod:`simulate.pipeline`) -- ``greybench machine``,
``rank-poses``, ``explain``, ``bench``, and the service's simulation and explain jobs -- reads its
defaults here, so a default changed here changes it everywhere. Each value says what it is for and
why it has this value.

Dexel spacing, one value per purpose:

- :data:`DEXEL_SPACING` (0.25 mm) for *one part* whose geometry is the result (``machine``,
  ``explain``, the service's explain jobs). At 1 mm the grid alone differed by 9 um RMS from a
  0.25 mm scan of the same part and was blamed on the tool radius by ``explain``; at 0.25 mm a
  machine-made scan explained with the same robot file names no cause.
- :data:`RANKING_DEXEL_SPACING` (0.5 mm) for *ranking placements* (``rank-poses``, the service's
  simulation jobs): it orders the placements as 0.25 mm does, at less than half the time, but a row's
  value carries a grid error of up to several tolerances. Measured with the two-mass drives (iso320,
  max100, 4 poses, 15 s against 36 s): the same best pose, scores within 2.4 %, rows within 86 µm of
  the 0.25 mm value (the angles row; the square side length up to 51 µm); iso160: rows within 128 µm, while
  0.25 mm stays within 25 µm of 0.125 mm (``docs/ideal-part.md``). The finishing passes take a 0.5 mm
  radial allowance, one dexel at 0.5 mm: the cutting force integrates over the dexels inside the
  tool, so coarse grids make force and deflection jump as whole dexels enter and leave the cutter.
  (An earlier measurement, with the rigid servo, had every row within 0.02 mm.)
"""
from __future__ import annotations

#: Dexel spacing [m] for simulating one part (module docstring).
DEXEL_SPACING = 0.25e-3
#: Dexel spacing [m] for ranking workpiece placements (module docstring).
RANKING_DEXEL_SPACING = 0.5e-3
#: Largest accepted dexel spacing [m]: coarser grids cannot resolve the 6 mm test-piece features.
MAX_DEXEL_SPACING = 5e-3
#: Virtual CMM probe point distance along a feature [m].
PROBE_SPACING = 2e-3
#: Workpiece material, a name in ``data/materials.toml``.
MATERIAL = "Al7075"
#: Spindle speed [rev/min] when the program never sets an S word (``machine`` only; the ranking
#: refuses such a program, since its cutting forces would rest on a guess).
SPINDLE_RPM = 12000.0
#: Interpolation cycle [s] (paper 3.1): one coupled-loop step.
CYCLE = 0.002
#: Stock left out below the lowest programmed cutting height [m] (ranking, explain): no tool reaches
#: it and it would only multiply the horizontal rays. ``machine`` keeps the whole stock (its
#: virtual workpiece is the whole part).
STOCK_FLOOR = 2e-3
#: Sample interval [s] of the axis records learned sequence models (LSTM) are trained on
#: (``greybench trajectory`` samples at 1 kHz). A black-box recurrent net has no time constant of
#: its own: it is stepped in the loop at the rate it was trained at (:mod:`simulate.robot.loop_friction`).
LEARNED_SAMPLE_PERIOD = 1e-3
