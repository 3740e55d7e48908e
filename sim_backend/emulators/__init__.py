"""Device emulators that speak the real wire protocols, so the real drivers run against the
simulated cell: ``val/`` (VAL II monitor), ``ati/`` (ATI F/T controller), ``magellan/``
(Magellan serial 3D mouse, for the real spacenavd), ``mjpeg/`` (the hand camera as an MJPEG
stream, served by the product's ``drivers.camera.mjpeg_server``). Shared: ``link`` (a byte protocol
served on a pty or TCP line from a thread: ``LinkServer``, the base of the VAL, ATI and
Magellan emulators), ``endpoints`` (pseudo-terminal and TCP endpoints), ``cell`` (one simulated
cell behind all of them, for hardware in the loop). Every emulator starts and stops through
``drivers.core.lifecycle`` (``start()`` / ``close()``; ``ThreadedServer``).
"""
