"""The service's Prometheus metrics (``service.metrics_port``): what they count, and the HTTP
port that serves them in the text format.

Counters and histograms are fed by the service's event stream (``EventHub.add_listener``):
``iteration`` (one look of the positioning loop), ``job`` (a job ended), ``abort`` (an abort
answered), ``fault`` (the service entered or renewed a fault) and ``state``. Gauges that describe
the present (connected clients, models in use) are read from the service when scraped. Each
service has a registry of its own, never prometheus_client's global one.

The port binds to ``service.metrics_address`` (127.0.0.1 by default). Bound anywhere else, every
request must carry ``Authorization: Bearer <token>`` with the TCP control token
(``service.tcp.token_file``); the config is refused at load without one.
"""

from __future__ import annotations

import hmac
import logging
import math
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from socketserver import ThreadingMixIn
from typing import Any
from wsgiref.simple_server import WSGIRequestHandler, WSGIServer, make_server

from prometheus_client import CollectorRegistry, Counter, Enum, Gauge, Histogram, make_wsgi_app
from prometheus_client.core import InfoMetricFamily
from prometheus_client.registry import Collector

from controller.service.config import is_loopback
from controller.service.jobs import BODIES
from controller.service.listeners import ListenerError
from controller.service.states import State

logger = logging.getLogger(__name__)

OUTCOMES = ("done", "failed", "aborted", "fault")  # controller.service.jobs.classify
# One look: grab + perceive + move. The simulated cell's looks take 0.05-1 s, a real VAL move
# up to a few seconds.
ITERATION_BUCKETS_S = (0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)
LOOK_BUCKETS = (1, 2, 3, 4, 5, 6, 8, 10, 15, 20, 30, 50)
# An abort answers once the arm acknowledged the halt, or after service.abort_wait_s.
ABORT_BUCKETS_S = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
REQUEST_TIMEOUT_S = 5.0  # a scraper that sends no complete request within this is cut off
POLL_S = 0.05  # how often the serving thread looks for a shutdown request


class _ServiceState(Collector):
    """What the service has now, read at each scrape: models in use per part."""

    def __init__(self, models: Callable[[], dict[str, dict[str, Any] | None]]) -> None:
        self._models = models

    def collect(self) -> Iterator[InfoMetricFamily]:
        family = InfoMetricFamily("finepos_model", "The model in use for each taught part "
                                  "(system and file as status reports them)", labels=["part"])
        for part, info in sorted(self._models().items()):
            if info is not None:
                family.add_metric([part], {"system": str(info["system"]),
                                           "file": str(info["file"])})
        yield family


class ServiceMetrics:
    """One service's metrics in a registry of its own; ``on_event`` is the hub listener.

    clients: the number of connected control clients now; models: {part: the model info
    ``status`` reports, None without one} now.
    """

    def __init__(self, clients: Callable[[], int],
                 models: Callable[[], dict[str, dict[str, Any] | None]]) -> None:
        self.registry = CollectorRegistry()
        registry = self.registry
        self.iteration_seconds = Histogram(
            "finepos_iteration_seconds", "One look of the positioning loop: grab, perceive and "
            "move (the iteration record's timings_ms)", buckets=ITERATION_BUCKETS_S,
            registry=registry)
        self.job_looks = Histogram(
            "finepos_job_looks", "Looks (iteration records) per position job",
            buckets=LOOK_BUCKETS, registry=registry)
        self.jobs = Counter("finepos_jobs", "Jobs ended, by kind and outcome",
                            ["kind", "outcome"], registry=registry)
        self.grasps = Counter("finepos_grasps", "Grasps ended (a grasp job, or a position job "
                              "with grasp), by result: held or failed", ["result"],
                              registry=registry)
        self.faults = Counter(
            "finepos_faults", "Faults entered or renewed, per device not active then (kind: its "
            "state) or once as device none (kind: disk_full, self_check or error)",
            ["device", "kind"], registry=registry)
        self.aborts = Counter("finepos_aborts", "Abort requests answered, by whether the arm "
                              "acknowledged the halt", ["halted"], registry=registry)
        self.abort_seconds = Histogram(
            "finepos_abort_seconds", "Time to answer an abort: the job preempted and the arm's "
            "halt acknowledged (or service.abort_wait_s spent)", buckets=ABORT_BUCKETS_S,
            registry=registry)
        self.state = Enum("finepos_state", "The service's state", registry=registry,
                          states=[state.value for state in State])
        Gauge("finepos_control_clients", "Control clients connected now (UNIX socket and "
              "authenticated TCP)", registry=registry).set_function(clients)
        Gauge("finepos_seconds_since_last_done_job", "Seconds since a job last ended done "
              "(since the service started, before the first)",
              registry=registry).set_function(self._seconds_since_done)
        registry.register(_ServiceState(models))
        for kind in BODIES:  # every series exists from the start, so rates start at 0
            for outcome in OUTCOMES:
                self.jobs.labels(kind, outcome)
        for result in ("held", "failed"):
            self.grasps.labels(result)
        for halted in ("true", "false"):
            self.aborts.labels(halted)
        self._lock = threading.Lock()
        self._looks = 0  # iteration records since the last job ended
        self._last_done_s = time.monotonic()

    def _seconds_since_done(self) -> float:
        with self._lock:
            return time.monotonic() - self._last_done_s

    def on_event(self, event: dict[str, Any]) -> None:
        """Count one event of the service's stream (the EventHub listener)."""
        kind = event.get("event")
        if kind == "iteration":
            self._on_iteration(event["record"])
        elif kind == "job":
            self._on_job(event["job"])
        elif kind == "abort":
            self.aborts.labels(str(bool(event["halted"])).lower()).inc()
            self.abort_seconds.observe(event["seconds"])
        elif kind == "fault":
            self._on_fault(event["code"], event["devices"])
        elif kind == "state":
            self.state.state(event["state"])

    def _on_iteration(self, record: dict[str, Any]) -> None:
        timings_ms = record.get("timings_ms") or {}
        seconds = sum(timings_ms.values()) / 1e3
        if math.isfinite(seconds):
            self.iteration_seconds.observe(seconds)
        with self._lock:
            self._looks += 1

    def _on_job(self, job: dict[str, Any]) -> None:
        with self._lock:
            looks, self._looks = self._looks, 0
            if job["outcome"] == "done":
                self._last_done_s = time.monotonic()
        self.jobs.labels(job["kind"], job["outcome"]).inc()
        if job["kind"] == "position":
            self.job_looks.observe(looks)
        result = job.get("result") or {}
        grasp = result if job["kind"] == "grasp" else result.get("grasp")
        if isinstance(grasp, dict) and "success" in grasp:
            self.grasps.labels("held" if grasp["success"] else "failed").inc()

    def _on_fault(self, code: str, devices: dict[str, str]) -> None:
        if not devices:
            self.faults.labels("none", code if code != "device" else "error").inc()
        for device, state in devices.items():
            self.faults.labels(device, state).inc()


def bearer_guard(app: Callable, token: str) -> Callable:
    """``app`` (WSGI) answering only requests with ``Authorization: Bearer <token>``; others get
    401 (compared in constant time)."""
    expected = f"Bearer {token}".encode()

    def guarded(environ: dict[str, Any], start_response: Callable) -> Iterable[bytes]:
        given = environ.get("HTTP_AUTHORIZATION", "").encode("latin-1", "replace")
        if not hmac.compare_digest(given, expected):
            start_response("401 Unauthorized", [("Content-Type", "text/plain; charset=utf-8"),
                                                ("WWW-Authenticate", 'Bearer realm="finepos"')])
            return [b"unauthorized: send Authorization: Bearer <service.tcp token>\n"]
        return app(environ, start_response)

    return guarded


class _Server(ThreadingMixIn, WSGIServer):
    daemon_threads = True  # a scrape in progress never holds up a shutdown


class _Server6(_Server):
    address_family = socket.AF_INET6


class _Handler(WSGIRequestHandler):
    timeout = REQUEST_TIMEOUT_S

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the base's name
        logger.debug("metrics %s: " + format, self.address_string(), *args)


class MetricsServer:
    """``metrics``' registry over HTTP on ``address``:``port``, served by a thread of its own
    from ``start`` until ``close``. ``token``: required as a Bearer token unless ``address``
    is loopback."""

    def __init__(self, metrics: ServiceMetrics, address: str, port: int,
                 token: str | None) -> None:
        app = make_wsgi_app(metrics.registry)
        self.guarded = not is_loopback(address, "service.metrics_address")
        if self.guarded:
            if token is None:
                raise ListenerError(f"service.metrics_address: {address} is not loopback and "
                                    "there is no service.tcp token")
            app = bearer_guard(app, token)
        server_class = _Server6 if ":" in address else _Server
        try:
            self._httpd = make_server(address, port, app, server_class, _Handler)
        except OSError as exc:
            raise ListenerError(f"service.metrics_port: cannot listen on {address}:{port}: "
                                f"{exc.strerror or exc}") from exc
        self.address, self.port = address, self._httpd.server_address[1]
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="metrics",
                                        kwargs={"poll_interval": POLL_S}, daemon=True)

    @property
    def url(self) -> str:
        """Where the metrics are served."""
        host = f"[{self.address}]" if ":" in self.address else self.address
        return f"http://{host}:{self.port}/metrics"

    def start(self) -> MetricsServer:
        """Start serving (returns self)."""
        self._thread.start()
        logger.info("metrics on %s%s", self.url, " (Bearer token required)" if self.guarded
                    else "")
        return self

    def close(self, timeout_s: float) -> None:
        """Stop serving and close the port, waiting at most about ``timeout_s`` for the thread
        (a scrape still being answered is left to its daemon thread)."""
        if self._thread.is_alive():
            self._httpd.shutdown()  # returns once serve_forever has (within POLL_S)
            self._thread.join(timeout_s)
        self._httpd.server_close()
