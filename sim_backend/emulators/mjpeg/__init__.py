"""The hand camera as an MJPEG-over-HTTP stream: ``server``, ``command`` (``finepos sim
mjpeg``), ``bench`` (``finepos bench camera-stream``).
"""
