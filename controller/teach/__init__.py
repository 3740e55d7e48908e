"""Teach-in: ``cell_state`` (what teach-in recorded), ``acquisition`` (the training grids taken
around the taught pose), ``spacenav`` (jogging with a 3D mouse through spacenavd).
"""
