"""The paper's two baseline systems (sections 2.2, 2.3, 4.2, 4.3), as pure functions on arrays:
``pca/`` (eigenimages and a B-spline neuro-fuzzy controller) and ``hough/`` (line Hough
transform, peak constellation, PSOM). ``grid`` indexes the training grid for both. They share
the Gabor system's front end (``calibration_free.front_end.FrontEnd``, trained by
``calibration_free.training.prepare_training``) and model file
(``calibration_free.model_file.TaughtModel``).
"""
