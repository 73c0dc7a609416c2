"""The engine: a scene composed into a Simulation, its step loop, adaptive stepping and the backends.

Imports the model and the contract, never the analysis, the files (``bark.io``) or the studies.
"""
