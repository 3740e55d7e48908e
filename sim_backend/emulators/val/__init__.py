"""VAL II monitor emulator: the PUMA 260 controller's terminal over a pty or TCP, fault knobs.

Modules: ``monitor`` (the protocol state machine over any Arm), ``kinematics`` (PUMA 260 joints),
``lines`` (input line splitting), ``server`` (ValEmulator, a ``LinkServer`` of
``sim_backend.emulators.link``, and ValFaults), ``sim_arm`` (the simulated cell's arm behind it),
``command`` (``finepos sim val-emulator``), ``bench`` (``finepos bench val``).
"""
