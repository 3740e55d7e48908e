"""The channels of a run recording and their JSON schemas (Foxglove's well-known ones and ours).

Foxglove's JSON encoding of its well-known schemas: times are ``{"sec", "nsec"}``, ``bytes``
fields are base64 strings, lengths are metres, colours are RGBA in 0..1. The schemas below are
the fields of ``foxglove.CompressedImage``, ``foxglove.ImageAnnotations`` and
``foxglove.FrameTransform`` that a recording uses, with Foxglove's field names and types, so
Foxglove Studio and other MCAP readers show the channels without configuration.
"""

from __future__ import annotations

from typing import Any

_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_POINT2 = {"type": "object", "title": "foxglove.Point2",
           "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
_COLOR = {"type": "object", "title": "foxglove.Color",
          "properties": {k: {"type": "number", "minimum": 0, "maximum": 1} for k in "rgba"}}
_VECTOR3 = {"type": "object", "title": "foxglove.Vector3",
            "properties": {k: {"type": "number"} for k in "xyz"}}
_QUATERNION = {"type": "object", "title": "foxglove.Quaternion",
               "properties": {k: {"type": "number"} for k in "xyzw"}}

COMPRESSED_IMAGE = {
    "title": "foxglove.CompressedImage", "type": "object",
    "description": "A compressed image",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string", "description": "Image format: jpeg, png or webp"},
    },
}

IMAGE_ANNOTATIONS = {
    "title": "foxglove.ImageAnnotations", "type": "object",
    "description": "Array of annotations for a 2D image",
    "properties": {
        "circles": {"type": "array", "items": {
            "type": "object", "title": "foxglove.CircleAnnotation",
            "properties": {"timestamp": _TIME, "position": _POINT2,
                           "diameter": {"type": "number"}, "thickness": {"type": "number"},
                           "fill_color": _COLOR, "outline_color": _COLOR}}},
        "points": {"type": "array", "items": {
            "type": "object", "title": "foxglove.PointsAnnotation",
            "properties": {"timestamp": _TIME,
                           "type": {"type": "integer", "description":
                                    "0 UNKNOWN, 1 POINTS, 2 LINE_LOOP, 3 LINE_STRIP, "
                                    "4 LINE_LIST"},
                           "points": {"type": "array", "items": _POINT2},
                           "outline_color": _COLOR,
                           "outline_colors": {"type": "array", "items": _COLOR},
                           "fill_color": _COLOR, "thickness": {"type": "number"}}}},
        "texts": {"type": "array", "items": {
            "type": "object", "title": "foxglove.TextAnnotation",
            "properties": {"timestamp": _TIME, "position": _POINT2, "text": {"type": "string"},
                           "font_size": {"type": "number"}, "text_color": _COLOR,
                           "background_color": _COLOR}}},
    },
}

FRAME_TRANSFORM = {
    "title": "foxglove.FrameTransform", "type": "object",
    "description": "A transform between two reference frames in 3D space",
    "properties": {"timestamp": _TIME, "parent_frame_id": {"type": "string"},
                   "child_frame_id": {"type": "string"}, "translation": _VECTOR3,
                   "rotation": _QUATERNION},
}

_STEP = {"type": ["object", "null"], "properties": {
    "dx_mm": {"type": "number"}, "dy_mm": {"type": "number"}, "dz_mm": {"type": "number"},
    "dphi_deg": {"type": "number"}}}

ITERATION_RECORD = {
    "title": "finepos.IterationRecord", "type": "object",
    "description": "One look of the positioning loop, as the JSON Lines iteration log stores "
                   "it (controller.loop.record.IterationRecord), plus the overlay geometry",
    "properties": {
        "time": {"type": "number"}, "run_id": {"type": "string"},
        "system": {"type": "string"}, "iteration": {"type": "integer"},
        "u_px": {"type": ["number", "null"]}, "v_px": {"type": ["number", "null"]},
        "status": {"type": "string", "enum": ["ok", "no_object", "ambiguous"]},
        "loop_kind": {"type": "string", "enum": ["half", "full", "around", "check", "stop"]},
        "loops": {"type": "number"}, "commanded": _STEP, "executed": _STEP,
        "clipped": {"type": "boolean"},
        "timings_ms": {"type": "object"},
        "error": {"type": ["object", "null"], "properties": {
            "x_mm": {"type": "number"}, "y_mm": {"type": "number"},
            "phi_deg": {"type": "number"}}},
        "overlay": {"type": "object", "description": "controller.recording.overlay.Overlay"},
    },
    "required": ["run_id", "iteration", "status", "loop_kind", "loops"],
}

GUARD_EVENT = {
    "title": "finepos.GuardEvent", "type": "object",
    "description": "The end of a force-guarded grasp: what ended it and whether it retreated",
    "properties": {"success": {"type": "boolean"}, "reason": {"type": "string"},
                   "depth_mm": {"type": "number"}, "width_mm": {"type": ["number", "null"]},
                   "max_force_n": {"type": "number"}, "retreated": {"type": "boolean"},
                   "held_weight_n": {"type": ["number", "null"]},
                   "closing_force_n": {"type": ["number", "null"]},
                   "carried_step": {"type": ["object", "null"],
                                    "description": "the positioning loop's converged step, "
                                                   "made by the first descent move"}},
    "required": ["success", "reason"],
}

WRENCH_READING = {
    "title": "finepos.WrenchReading", "type": "object",
    "description": "One wrist force/torque reading (sensor frame, z = approach axis)",
    "properties": {k: {"type": "number"} for k in
                   ("fx_n", "fy_n", "fz_n", "tx_nm", "ty_nm", "tz_nm")},
    "required": ["fx_n", "fy_n", "fz_n", "tx_nm", "ty_nm", "tz_nm"],
}

# topic -> (schema name, schema): every channel a recording may hold.
CHANNELS: dict[str, tuple[str, dict[str, Any]]] = {
    "/hand_camera/image": ("foxglove.CompressedImage", COMPRESSED_IMAGE),
    "/hand_camera/annotations": ("foxglove.ImageAnnotations", IMAGE_ANNOTATIONS),
    "/tf": ("foxglove.FrameTransform", FRAME_TRANSFORM),
    "/finepos/iteration": ("finepos.IterationRecord", ITERATION_RECORD),
    "/finepos/guard_event": ("finepos.GuardEvent", GUARD_EVENT),
    "/finepos/wrench": ("finepos.WrenchReading", WRENCH_READING),
}
IMAGE_TOPIC = "/hand_camera/image"
ANNOTATIONS_TOPIC = "/hand_camera/annotations"
TF_TOPIC = "/tf"
ITERATION_TOPIC = "/finepos/iteration"
GUARD_TOPIC = "/finepos/guard_event"
WRENCH_TOPIC = "/finepos/wrench"
CAMERA_FRAME = "hand_camera"
