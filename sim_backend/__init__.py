"""The simulated PUMA 260 work cell and the emulators of its devices.

``cell/`` (the PyBullet cell: arm, gripper, hand camera, parts, light, contact), ``devices``
(SimArm, SimCamera, SimWrenchSensor: the device interfaces on a SimCell), ``emulators/`` (the
VAL, ATI, Magellan and MJPEG emulators on real pseudo-terminals and sockets), and the CLI
leaves ``snapshot`` and ``bench``. Nothing here has import-time side effects.
"""
