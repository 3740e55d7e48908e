"""Teach-in: ``cell_state`` (what teach-in recorded), ``state_folder`` (each part's folder of
teach-in, datasets and models), ``acquisition`` (the training grids taken around the taught
pose), ``spacenav`` (jogging with a 3D mouse through spacenavd).
"""
