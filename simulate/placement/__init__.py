"""Placement optimisation: search the workpiece pose the machining simulation scores best.

- :mod:`simulate.placement.screen` -- the cheap screen (reach, joint-limit margin, wrist
  singularity along the whole program) and the score proxies (switching points, compliance);
- :mod:`simulate.placement.search` -- the budgeted, seeded search (Optuna TPE), simulating each
  promising candidate with the ranking's score through :func:`simulate.pipeline.run_job`;
- :mod:`simulate.placement.report` -- ``best.json``, the markdown report and the heat map.

``greybench optimize-pose`` and the service's placement-search jobs call these. Method and sources:
``docs/placement-search.md``.
"""
