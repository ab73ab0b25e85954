"""identify: joint friction identification from measured axis records.

Trajectories to excite a joint, the axis-record data format, a plant that makes synthetic
records, friction models with one estimator contract, fitting, tracking and diagnosis.
Imports nothing else of greybench.
"""
