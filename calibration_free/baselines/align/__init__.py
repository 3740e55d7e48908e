"""An image-alignment servo, the kind a vision engineer builds with OpenCV: the part's soft
silhouette registered to the taught pose's (``register``: a rotation scan seeded by the blob,
then ``cv2.findTransformECC``), and least squares from the image shift and turn to the tool
step (``model``, ``train``). Not in the paper: the comparison a cell owner would make.
"""
