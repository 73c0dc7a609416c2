"""Files: a run's outputs, recorders along the way, meshes, checkpoints and run folders.

Sits on the engine and the analysis; never imported by them.
"""
