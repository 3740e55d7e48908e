"""ATI F/T controller emulator: ``protocol`` (the serial ASCII protocol over any wrench
sensor), ``emulator`` (served on a pty or TCP, with fault knobs), ``command`` (``finepos sim
ati-emulator``), ``bench`` (``finepos bench ati``).
"""
