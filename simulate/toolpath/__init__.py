"""Toolpath: G-code in, jerk-limited interpolation at the 2 ms cycle, placement on the robot,
joint trajectories and switching points out (paper sections 3.1, 3.2, 3.7)."""
