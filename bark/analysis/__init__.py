"""Patterns measured and compared: circular statistics, PCA of patches, Hellinger distances, quartets.

Works on plain arrays (points and patch ids), so it serves simulated bark and bark digitised from
photographs alike: imports the model and the base modules only, never the engine.
"""
