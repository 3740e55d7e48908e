"""Device emulators that speak the real wire protocols, so the real drivers run against the
simulated cell: ``val/`` (VAL II monitor), ``ati/`` (ATI F/T controller), ``magellan/``
(Magellan serial 3D mouse, for the real spacenavd), ``mjpeg/`` (the hand camera as an MJPEG
stream). Shared: ``link`` (a byte protocol served on a link in a background thread),
``endpoints`` (pseudo-terminal and TCP endpoints), ``cell`` (one simulated cell behind all of
them, for hardware in the loop).
"""
