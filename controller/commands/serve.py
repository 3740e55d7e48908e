"""``finepos serve``: run the controller as a long-running service (see ``controller.service``)."""

from __future__ import annotations

from controller.commands.common import add_command, add_config_file_option
from controller.config import load_config
from controller.service.sd_notify import Notifier
from controller.service.service import Service
from controller.service.signals import service_signals


def cmd_serve(args) -> int:
    """Run the service until SIGTERM (SIGHUP reloads); returns its exit status."""
    config = load_config(args.config)
    notifier = Notifier()
    try:
        service = Service(config, socket_path=args.socket, notifier=notifier,
                          reload_config=(lambda: load_config(args.config)) if args.config
                          else None)
        with service_signals(service.stop, service.request_reload):
            return service.run()
    finally:
        notifier.close()


def register(subparsers) -> None:
    """Add ``finepos serve``."""
    p = add_command(
        subparsers, "serve",
        help="run the controller service (control socket, systemd notify)",
        description="Example: finepos serve --config deploy/finepos.yaml --socket /tmp/fp.sock"
                    "\n\nOwn the configured devices (the simulated cell without a config) and "
                    "serve the control API (JSON lines) on a UNIX socket; `finepos ctl` is its "
                    "client. SIGTERM stops (halting any motion), SIGHUP reloads the config and "
                    "the model (a bad one is refused, the old one kept). Under systemd "
                    "(Type=notify) it reports READY, STATUS, WATCHDOG and STOPPING.")
    add_config_file_option(p)
    p.add_argument("--socket", metavar="PATH",
                   help="control socket (default: service.socket_path, "
                        "/run/finepos/finepos.sock)")
    p.set_defaults(func=cmd_serve)
