"""The vision systems the positioning loop can run: the estimator contract (``estimator``),
the registry (``registry``) and one module per system.
"""
