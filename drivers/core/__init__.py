"""The shared core of finepos: typed errors, pose math, strict config loading, atomic files,
the parts catalogue, the taught cell's state (``cell_state``, read by every vision system
and teach-in), and the start/stop lifecycle of servers and emulators.

Imports nothing else of finepos, so every package (drivers, calibration_free, sim_backend,
controller) can build on it without a circle.
"""
