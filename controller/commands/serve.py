"""Run the controller service (control socket, systemd notify).

Own the configured devices (the simulated cell without a config) and serve the control API (JSON
lines) on a UNIX socket; `finepos ctl` is its client. SIGTERM stops (halting any motion), SIGHUP
reloads the config and the model (a bad one is refused, the old one kept). Under systemd
(Type=notify) it reports READY, STATUS, WATCHDOG and STOPPING.

Example: finepos serve --config deploy/finepos.yaml --socket /tmp/fp.sock
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os

from controller.commands.common import add_config_file_option, port_number
from controller.config import load_config
from controller.service.config import LIVE_PORT, LiveConfig
from controller.service.sd_notify import Notifier
from controller.service.service import Service
from controller.service.signals import service_signals


def _load(args):
    """The config of ``--config``, with the live view of ``--live PORT`` (on
    ``service.live.address``)."""
    config = load_config(args.config)
    if args.live is None:
        return config
    live = config.service.live or LiveConfig()
    return dataclasses.replace(config, service=dataclasses.replace(
        config.service, live=dataclasses.replace(live, port=args.live)))


def run(args) -> int:
    """Run the service until SIGTERM (SIGHUP reloads); returns its exit status."""
    config = _load(args)
    notifier = Notifier()
    try:
        service = Service(config, socket_path=args.socket, notifier=notifier,
                          reload_config=(lambda: _load(args)) if args.config else None)
        with service_signals(service.stop, service.request_reload):
            status = service.run()
    finally:
        notifier.close()
    if service.job_still_running():
        # A train cannot be interrupted: the devices, sockets and logs are closed, its files are
        # written atomically (the old ones stay), so end here rather than let the interpreter's
        # finalizers run under a thread in native code (that aborts the process).
        logging.shutdown()
        os._exit(status)
    return status


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos serve``."""
    add_config_file_option(parser)
    parser.add_argument("--socket", metavar="PATH",
                        help="control socket (default: service.socket_path, "
                             "/run/finepos/finepos.sock)")
    parser.add_argument("--live", type=port_number, nargs="?", const=LIVE_PORT,
                        metavar="PORT",
                        help="serve every job live for Foxglove (a Foxglove WebSocket on "
                             f"service.live.address, 127.0.0.1 by default) at PORT (default "
                             f"{LIVE_PORT}); overrides service.live.port")
