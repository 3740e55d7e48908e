"""The paper's two baseline systems (sections 2.2, 2.3, 4.2, 4.3), as pure functions on arrays.

PCA system: ``eigenimages`` (PCA of ROIs), ``bspline`` and ``fuzzy_controller`` (the B-spline
neuro-fuzzy controller), ``pca_model`` (the trained model and its perception), ``pca_train``.

Hough system: ``edges`` (smoothing, edge filter, binarisation, masking of inner edges),
``hough`` (straight-line Hough transform with the back-transform), ``constellation`` (the model
of the expected peak constellation), ``angle_map`` (constellation angle -> rotation), ``grid``
and ``psom`` (the parametrised self-organising map for the translation), ``hough_model``,
``hough_train``.

Shared: ``front_end`` (the Gabor system's preprocessing and localisation, as stored in a
baseline model); the file format is ``calibration_free.model_file``, as for the Gabor bundle.
"""
