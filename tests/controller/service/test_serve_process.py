"""``finepos serve`` as systemd runs it: a subprocess on the simulated cell with a NOTIFY_SOCKET
and a watchdog; driven through ``finepos ctl`` and the client; SIGHUP reloads (a bad config is
refused); SIGTERM in mid-motion stops it within 3 s with the iteration log intact."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from controller.loop.iteration_log import read_log
from controller.service.client import ServiceClient
from tests.controller.service.conftest import EVENT_TIMEOUT_S, START_TIMEOUT_S

REPO = Path(__file__).resolve().parents[3]
STOP_LIMIT_S = 3.0  # the check: SIGTERM in mid-motion stops within 3 s
JOB_TIMEOUT_S = 120.0


def write_config(path: Path, work: Path, **loop) -> None:
    path.write_text(yaml.safe_dump({
        "controller": {"paths": {"state_dir": str(work / "state"), "log_dir": str(work / "log")},
                       # never converges: a long positioning run keeps moving until aborted
                       "loop": {"converge_mm": 0.0, "converge_deg": 0.0, **loop}},
        "service": {"socket_path": str(work / "fp.sock"), "idle_poll_s": 0.5},
    }))


@pytest.mark.slow
def test_serve_under_systemd_protocol(short_dir, notify_socket):
    config = short_dir / "finepos.yaml"
    write_config(config, short_dir)
    env = {**os.environ, "NOTIFY_SOCKET": str(notify_socket.path), "WATCHDOG_USEC": "400000"}
    env.pop("WATCHDOG_PID", None)
    command = [sys.executable, "-m", "controller.cli", "serve", "--config", str(config)]
    with open(short_dir / "serve.log", "wb") as serve_log, \
            subprocess.Popen(command, env=env, cwd=REPO, stdout=serve_log,
                             stderr=subprocess.STDOUT) as process:
        try:
            notify_socket.wait_for(lambda m: m.startswith("READY=1"), START_TIMEOUT_S)
            notify_socket.wait_for(lambda m: m == "WATCHDOG=1")
            notify_socket.wait_for(lambda m: m == "WATCHDOG=1")
            sock = short_dir / "fp.sock"

            taught = subprocess.run([sys.executable, "-m", "controller.cli", "ctl", "--socket",
                                     str(sock), "teach", "--auto"], cwd=REPO, text=True,
                                    capture_output=True, timeout=JOB_TIMEOUT_S)
            assert taught.returncode == 0, taught.stderr
            assert json.loads(taught.stdout)["job"]["outcome"] == "done"
            notify_socket.wait_for(lambda m: m.startswith("STATUS=idle: job 1 (teach) done"))

            with ServiceClient(sock, timeout_s=JOB_TIMEOUT_S) as client:
                for cmd, args in (("acquire", {"set": "nn1"}), ("acquire", {"set": "nn2"}),
                                  ("train", {})):
                    assert client.call(cmd, timeout_s=JOB_TIMEOUT_S, wait=True,
                                       **args)["job"]["outcome"] == "done"
                job = client.call("position", wait=True, offset=[12, -8, 20], max_loops=2)["job"]
                assert job["outcome"] == "done" and job["result"]["outcome"] == "budget"
                assert client.call("status")["model"]["system"] == "gabor"

                config.write_text("controller: {loop: {max_loops: -1}}\n")
                process.send_signal(signal.SIGHUP)
                notify_socket.wait_for(lambda m: "reload refused" in m)
                assert client.call("status")["config"]["last_reload"]["ok"] is False
                write_config(config, short_dir, max_loops=5.0)
                process.send_signal(signal.SIGHUP)
                notify_socket.wait_for(lambda m: "reload config" in m and "reloaded" in m)

            with ServiceClient(sock, timeout_s=EVENT_TIMEOUT_S) as watcher, \
                    ServiceClient(sock, timeout_s=EVENT_TIMEOUT_S) as client:
                events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
                client.call("position", offset=[15, 10, -25], max_loops=500)
                streamed = []
                for event in events:
                    if event["event"] == "iteration":
                        streamed.append(event["record"])
                    if len(streamed) == 3:
                        break
                # the watcher goes on reading while the service stops, as `finepos ctl stream`
                # does: a client that stops reading is cut off once its socket's buffer is
                # full, without the stream's "end"
                rest: list[dict] = []  # what the service sent before it went away
                reader = threading.Thread(target=lambda: rest.extend(events), daemon=True)
                reader.start()
                process.send_signal(signal.SIGTERM)
                sent_s = time.monotonic()
                assert process.wait(timeout=STOP_LIMIT_S + 5.0) == 0
                assert time.monotonic() - sent_s < STOP_LIMIT_S
                reader.join(EVENT_TIMEOUT_S)
                assert not reader.is_alive()
                assert rest[-1] == {"event": "end", "reason": "service stopping"}
                assert [e["state"] for e in rest if e["event"] == "state"] == ["stopping"]
        finally:
            if process.poll() is None:
                process.kill()
    notify_socket.drain()
    assert any(m.startswith("STOPPING=1") for m in notify_socket.messages)
    assert not (short_dir / "fp.sock").exists()
    records = read_log(short_dir / "log" / "iterations.jsonl")  # every line valid JSON
    run = [r for r in records if r["run_id"] == streamed[0]["run_id"]]
    assert run[:3] == streamed and len(run) >= 3
    log_lines = [line for line in (short_dir / "serve.log").read_text().splitlines()
                 if " INFO " in line or " ERROR " in line]
    assert "resolved config" in log_lines[0]
    assert "stop requested" in log_lines[-2] and log_lines[-1].endswith("stopped")
