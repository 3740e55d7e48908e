"""``finepos sim ...`` (the simulated cell and its device emulators), ``finepos bench ...``
(benchmarks that print JSON numbers: medians, ratios) and ``finepos docs ...`` (reference pages
generated from the code): command groups whose leaves live in other packages (see
``controller.commands.leaves``)."""

from controller.commands.leaves import register_group

SIM_LEAVES = {
    "val-emulator": "sim_backend.emulators.val.command",
    "snapshot": "sim_backend.snapshot",
    "magellan-emulator": "sim_backend.emulators.magellan.command",
    "ati-emulator": "sim_backend.emulators.ati.command",
    "camera-stream": "sim_backend.emulators.mjpeg.command",
}
BENCH_LEAVES = {
    "val": "sim_backend.emulators.val.bench",
    "sim": "sim_backend.bench",
    "perception": "calibration_free.bench",
    "service": "controller.service.bench",
    "soak": "controller.service.soak",
    "ati": "sim_backend.emulators.ati.bench",
    "camera-stream": "sim_backend.emulators.mjpeg.bench",
    "recording": "controller.recording.bench",
    "symmetry": "controller.evaluation.symmetry_bench",
    "ablation": "controller.evaluation.ablation",
}

DOCS_LEAVES = {
    "config": "controller.docs.config_reference",
    "results": "controller.docs.results_page",
}


def register(subparsers) -> None:
    """Add ``finepos sim``, ``finepos bench`` and ``finepos docs``, one leaf per entry of their
    tables."""
    register_group(subparsers, "sim", "the simulated work cell and device emulators",
                   SIM_LEAVES)
    register_group(subparsers, "bench", "benchmarks that print JSON", BENCH_LEAVES)
    register_group(subparsers, "docs", "write the reference pages generated from the code",
                   DOCS_LEAVES)
