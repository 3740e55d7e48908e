"""The systems finepos is compared with, as pure functions on arrays: the paper's two baselines
(sections 2.2, 2.3, 4.2, 4.3), ``pca/`` (eigenimages and a B-spline neuro-fuzzy controller) and
``hough/`` (line Hough transform, peak constellation, PSOM), and ``align/``, an image-alignment
servo (silhouette registration with ECC, least squares to the tool step). ``grid`` indexes the
training grid for the paper's two. They share the Gabor system's front end
(``calibration_free.front_end.FrontEnd``, trained by ``calibration_free.training.
prepare_training``) and model file (``calibration_free.model_file.TaughtModel``).
"""
