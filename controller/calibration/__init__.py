"""The calibrations a model takes on the cell, one entry point each: ``rezero.rezero`` (a new
zero at the taught pose in the cell's light), ``heading_zero.read_heading_zero`` (a zero for
each heading of the tool) and ``self_check.self_check`` (does the model still read zero at the
taught pose). Each asks the vision system what it supports (``VisionSystem.rezeroes``,
``zero_by_heading``).
"""
