"""The model: the leaf-base lattice and its state, the springs' forces, the trunk's geometry.

Plain arrays and the paper's equations; imports nothing of bark but the base modules
(``bark.errors``, ``bark.units``, ``bark.validators``).
"""
