"""The shared core of finepos: typed errors, pose math, strict config loading, atomic files,
the parts catalogue, and the start/stop lifecycle of servers and emulators.

Imports nothing else of finepos, so every package (drivers, calibration_free, sim_backend,
controller) can build on it without a circle.
"""
