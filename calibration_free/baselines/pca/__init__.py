"""The paper's PCA system (sections 2.2, 4.2): ``eigenimages`` (PCA of ROIs), ``bspline`` and
``fuzzy_controller`` (the B-spline neuro-fuzzy controller), ``model`` (the trained model and
its perception of a frame) and ``train``.
"""
