"""Subcommands of the ``finepos`` CLI, one module each (listed in ``controller.cli``)."""
