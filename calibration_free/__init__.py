"""Calibration-free perception and learning: Gabor features of the hand-camera image, NN1/NN2.

Pure functions on images and arrays; nothing here talks to a robot. The path for one frame is
``preprocess`` (max channel, intensity normalisation) -> ``localise`` (object centre) -> ``roi``
(50x50 window) -> ``gabor`` (36 features) -> ``mlp`` (NN1: centre -> translation, NN2:
features -> rotation through the ``angles`` codec). ``pipeline`` ties these together for
training and inference, ``bundle`` stores a trained model, ``dataset`` stores training images.
``synthetic`` draws test scenes, ``baseline`` is the cv2.filter2D alternative that ``bench``
(``finepos bench perception``) times against, ``errors`` holds the typed errors.
"""
