"""``finepos bench ...``: benchmarks that print JSON numbers (medians, ratios)."""

from controller.commands.leaves import register_group

LEAVES = {
    "val": "sim_backend.emulators.val.bench",
    "sim": "sim_backend.bench",
    "perception": "calibration_free.bench",
    "service": "controller.service.bench",
    "ati": "sim_backend.emulators.ati.bench",
    "camera-stream": "sim_backend.emulators.mjpeg.bench",
}


def register(subparsers) -> None:
    """Add ``finepos bench`` with one leaf per LEAVES entry."""
    register_group(subparsers, "bench", "benchmarks that print JSON", LEAVES)
