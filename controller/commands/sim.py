"""``finepos sim ...``: the simulated work cell and its device emulators."""

from controller.commands.leaves import register_group

LEAVES = {
    "val-emulator": "sim_backend.val_emulator.command",
    "snapshot": "sim_backend.snapshot",
    "magellan-emulator": "sim_backend.magellan_cli",
    "ati-emulator": "sim_backend.ati_emulator_cli",
    "camera-stream": "sim_backend.mjpeg_cli",
}


def register(subparsers) -> None:
    register_group(subparsers, "sim", "the simulated work cell and device emulators", LEAVES)
