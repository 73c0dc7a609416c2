"""Studies built on runs: one run with its outputs (``runner``), sweeps, work-precision.

The top layer of the core: imports anything below, and nothing below imports it.
"""
