"""Magellan serial 3D-mouse emulator: ``protocol`` (the mouse's packets), ``emulator`` (on a
pty), ``spacenavd`` (the real daemon run against it), ``keyboard`` and ``script`` (what drives
it), ``command`` (``finepos sim magellan-emulator``).
"""
