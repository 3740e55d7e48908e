"""The paper's Hough system (sections 2.3, 4.3): ``edges`` (smoothing, edge filter, masking of
inner edges), ``transform`` (straight-line Hough transform with the back-transform),
``constellation`` (the model of the expected peak constellation), ``angle_map`` (constellation
angle -> rotation), ``psom`` (the parametrised self-organising map for the translation),
``model`` (the trained model and its perception of a frame) and ``train``.
"""
