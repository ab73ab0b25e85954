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
- :data:`RANKING_DEXEL_SPACING` (0.25 mm) for *ranking placements* and *compensating* (``rank-poses``,
  ``compensate``, ``optimize-pose``, the service's simulation, compensation and placement jobs):
  a row's value there must be right to about a tolerance, since the compensation corrects against it
  and the acceptance judges it. Measured with the two-mass drives (iso160, max100): 0.25 mm stays
  within 25 µm of 0.125 mm on every row, while 0.5 mm was up to 128 µm off (near's angles row). The
  finishing passes take a 0.5 mm radial allowance, one dexel at 0.5 mm: on the 30/60 deg edges, which
  cross the grid obliquely, the cutting force then jumped by 45 N (standard deviation along an edge,
  9 N at 0.25 mm) as whole dexels entered and left the cutter, and the drives' play turned that into
  a 250 µm over-cut where 0.25 mm predicts 70 µm left standing. 0.5 mm orders iso320's four poses
  as 0.25 mm does (scores within 2.4 %, rows within 86 µm) at 15 s against 36 s; an earlier
  measurement, with the rigid servo, had every row within 0.02 mm at 0.5 mm, which is why that was
  the default (``docs/ideal-part.md``).
"""
from __future__ import annotations

#: Dexel spacing [m] for simulating one part (module docstring).
DEXEL_SPACING = 0.25e-3
#: Dexel spacing [m] for ranking workpiece placements (module docstring).
RANKING_DEXEL_SPACING = 0.25e-3
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
