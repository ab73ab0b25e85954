"""simulate: robot model, toolpath interpolation, material removal, cutting forces,
evaluation and pose ranking. May use :mod:`identify` for friction model loading."""
