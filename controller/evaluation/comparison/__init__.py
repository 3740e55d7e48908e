"""The paper's comparison experiments on the simulated cell: Table 1 and the Fig. 5 filter search.

``table1``: the three systems x good and poor light, same seeds, one report per pair.
``filter_search``: Gabor filter configurations (``filter_sets``) trained and evaluated repeatedly.
``pools``: where the independent jobs run (in-process, local processes, or a Ray cluster).
``table1_report`` and ``filter_report`` render the results as markdown, JSON and plots.
"""
