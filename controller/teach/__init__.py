"""Teach-in: ``state_folder`` (each part's folder of teach-in, datasets and models; what
teach-in recorded is ``drivers.core.cell_state``), ``acquisition`` (the training grids taken
around the taught pose), ``spacenav`` (jogging with a 3D mouse through spacenavd).
"""
