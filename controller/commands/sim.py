"""``finepos sim ...``: the simulated work cell and its device emulators."""

from controller.commands.leaves import register_group

LEAVES = {
    "val-emulator": "sim_backend.emulators.val.command",
    "snapshot": "sim_backend.snapshot",
    "magellan-emulator": "sim_backend.emulators.magellan.command",
    "ati-emulator": "sim_backend.emulators.ati.command",
    "camera-stream": "sim_backend.emulators.mjpeg.command",
}


def register(subparsers) -> None:
    """Add ``finepos sim`` with one leaf per LEAVES entry."""
    register_group(subparsers, "sim", "the simulated work cell and device emulators", LEAVES)
