"""The positioning loop and what it hands over to: ``positioning`` (half and full loops),
``iteration_log`` (one JSON line per iteration), ``grasp`` and ``guards`` (the force-guarded
grasp).
"""
