"""The simulated work cell (PyBullet, DIRECT mode).

``scene_config`` (the ``scene:`` YAML section and the simulated arm's options), ``puma260`` (DH
kinematics), ``meshes`` and ``objects`` (the parts' geometry, for the kinds in the shared parts
catalogue), ``robot_model`` (arm, gripper and camera housing as a PyBullet multibody),
``hand_camera``, ``lighting`` and ``shadows``, ``textures``, ``contact`` (wrench and gripper
contact model), ``sim_cell`` (SimCell, the whole cell), ``pybullet_quiet`` (the import without
the build banner).
"""
