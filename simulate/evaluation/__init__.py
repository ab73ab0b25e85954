"""Process evaluation (paper sections 3.8 and 4): virtual CMM on the virtual workpiece, least-squares and
minimum-zone fits, the ISO 10791-7 feature table (paper Table 2), pose ranking, reports and tracing
surface points back to program lines and times."""
