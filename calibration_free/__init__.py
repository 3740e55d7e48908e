"""Calibration-free perception and learning: the hand-camera image -> the corrective step.

Pure functions and models on images and arrays; nothing here talks to a robot (of the rest of
finepos it imports only ``drivers.core``).

One frame, the Gabor system (the paper's): ``front_end`` (``FrontEnd``: ``preprocess`` max
channel and intensity normalisation, or saturation; ``localise`` the object's centre) ->
``roi`` (50x50 window) -> ``gabor`` (36 features) -> ``mlp`` (NN1: centre -> translation, NN2:
features -> rotation through the ``angles`` codec). ``perception`` runs a trained bundle on a
frame (``Perception.translation``, ``rotation`` going on from that percept, ``perceive`` for
both) through the named ``stages`` (localiser, the occlusion fallbacks ``ends`` and
``outline``, NN2 and the long ``axis``, the translation nets); ``training`` learns the front
end (``prepare_training``) and the networks (``train_bundle``, ``train_nn2``) from ``dataset``
files; ``bundle`` is the trained model, stored through ``model_file`` (``TaughtModel``: every
system's save and load).

``baselines`` holds the paper's two other systems on the same front end and model file:
``baselines/pca`` (eigenimages, B-spline fuzzy controller) and ``baselines/hough`` (line Hough
transform, peak constellation, PSOM). Building blocks: ``preprocess``, ``localise``.
``synthetic`` draws test scenes; ``filter2d_reference`` is the cv2.filter2D feature extractor
that ``bench`` (``finepos bench perception``) times against; ``errors`` holds the typed errors.
"""
