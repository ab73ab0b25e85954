"""Machining simulation (paper section 3.3-3.5): tri-dexel workpiece, cutters, material removal,
engagement and cutting forces, coupled with robot deflection and servo tracking error."""
