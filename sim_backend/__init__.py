"""The simulated PUMA 260 work cell (PyBullet, DIRECT mode), its devices and emulators.

Work cell: ``scene_config`` (the ``scene:`` YAML section and the simulated arm's options),
``puma260`` (DH kinematics), ``meshes`` and ``objects`` (procedural toy construction-set parts),
``robot_model`` (arm, gripper and camera housing as a PyBullet multibody), ``hand_camera``,
``lighting`` and ``shadows`` (light presets, cast shadows), ``textures``, ``contact`` (wrench
and gripper contact model), ``cell`` (SimCell, the whole cell), ``devices`` (SimArm, SimCamera,
SimWrenchSensor) and the CLI leaves ``snapshot`` and ``bench``. The serial/network device
emulators (``val_emulator*``, ``ati_emulator*``, ``magellan*``, ``mjpeg*``) describe themselves.
Nothing here has import-time side effects.
"""
