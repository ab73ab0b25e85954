"""Benchmarks whose work is more than a table of timings (the CLI in :mod:`greybench.commands` stays thin)."""
