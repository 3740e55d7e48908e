"""VAL II monitor emulator: the PUMA 260 controller's terminal over a pty or TCP, fault knobs.

Modules: ``monitor`` (the protocol state machine over any Arm), ``kinematics`` (PUMA 260 joints),
``lines`` (input line splitting), ``endpoints`` (pty and TCP), ``server`` (ValEmulator, ValFaults),
``command`` (``finepos sim val-emulator``), ``bench`` (``finepos bench val``).
"""
