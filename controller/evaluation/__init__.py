"""Evaluation on the simulated cell: ``trials`` (train, then position from random placements),
``metrics`` (the paper's accuracy figures), ``plots``, ``hil`` (the real drivers against the
emulators) and ``comparison/`` (Table 1 and the Fig. 5 filter search).
"""
