"""What a config reload (SIGHUP) may change while the service runs, and what needs a restart.

Live: ``safety`` (the arm's limits), ``controller`` (except the log folder, whose file is open,
and the state folder, whose lock is held; the recipe comes with the models, which a reload
reads again), and in ``service`` the allowed peers,
the idle poll, the reconnection backoff and the stall and stop timeouts. Everything else is
fixed by what is open: the devices (``arm``, ``camera``, ``wrench``, and ``scene`` for the
simulated cell), the log and state folders and the listeners (the control socket, the TCP
port, the metrics port). A reload that changes any of those
is refused as a whole.
"""

from __future__ import annotations

RESTART_SECTIONS = ("arm", "camera", "wrench", "scene")
RESTART_SERVICE_KEYS = ("socket_path", "socket_group", "max_request_bytes", "max_clients", "tcp",
                        "max_clients_per_uid", "max_waiting", "idle_timeout_s",
                        "request_timeout_s", "request_rate_hz", "request_burst",
                        "metrics_port", "metrics_address")


def restart_only_changes(old, new) -> list[str]:
    """The keys that differ between two FineposConfigs and cannot change without a restart."""
    changed = [name for name in RESTART_SECTIONS if getattr(old, name) != getattr(new, name)]
    changed += [f"service.{key}" for key in RESTART_SERVICE_KEYS
                if getattr(old.service, key) != getattr(new.service, key)]
    changed += [f"controller.paths.{key}" for key in ("log_dir", "state_dir")
                if getattr(old.controller.paths, key) != getattr(new.controller.paths, key)]
    return changed
