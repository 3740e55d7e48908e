"""Device interfaces, pose math, safety layer and hardware drivers of finepos.

Units at every interface: millimetres and degrees (what VAL speaks); radians only inside math.
"""
