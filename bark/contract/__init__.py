"""The plugin contract: the strategy base classes, the compiled parts they declare, the registry.

What a plugin author subclasses and what bark's own built-ins (``bark_plugins``) use, no more:
imports the model and the base modules only.
"""
