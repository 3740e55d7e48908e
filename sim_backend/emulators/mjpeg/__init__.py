"""The hand camera as an MJPEG-over-HTTP stream, served by the product's stream server
(``drivers.camera.mjpeg_server``): ``command`` (``finepos sim camera-stream``), ``bench``
(``finepos bench camera-stream``).
"""
