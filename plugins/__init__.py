"""bark's built-in strategies, installed as ``bark_plugins``.

They are registered in bark's ``pyproject.toml`` under the same entry-point groups a third-party
plugin uses (``bark.growth``, ``bark.integrator``, ``bark.breaker``, ``bark.analyzer``), so the one
lookup path in :mod:`bark.contract.registry` serves both.
"""
