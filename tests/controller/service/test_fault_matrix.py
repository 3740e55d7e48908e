"""The hardening probes of issue 15, each reproduced over real parts (a pty VAL emulator, the real
control socket, a real signal, a small tmpfs, a failing writer) and each ending in a typed error
or a clean refusal, with the service still answering ``status`` afterwards.

Time bounds asserted here are generous ceilings far below the waits the faults would cause
(a link's 30 s move timeout, 2 s per silent client): they catch a hang, not a slow machine.
"""

from __future__ import annotations

import contextlib
import inspect
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration_free.bundle import ModelBundle
from controller.loop.iteration_log import IterationLog, LogWriteError, read_log, scan_log
from controller.service.client import ServiceClient, ServiceError
from controller.service.service import Service
from drivers.core.pose import ToolStep
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.val.server import ValFaults
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    NOMINAL,
    START_TIMEOUT_S,
    client_for,
    copy_state,
    cube_view,
    device_opener,
    free_port,
    next_state_event,
    running_service,
    service_config,
    token_file,
    wait_for_state,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

REPO = Path(__file__).resolve().parents[3]
TEACH = {"grasp_depth_mm": 5.0, "object_width_mm": 30.0}
HANG_S = 30.0  # the dead link's move timeout: what an abort or a stop must not wait for
BOUND_S = 5.0  # ceiling for "answered at once" / "stopped in time" (far below HANG_S)


def val_arm(url: str, exchange_timeout_s: float = 0.5,
            move_timeout_s: float = 0.5) -> ValArm:
    return ValArm(ValConfig(port=url, exchange_timeout_s=exchange_timeout_s,
                            move_timeout_s=move_timeout_s), SafetyLimits())


def timed(call):
    start = time.monotonic()
    result = call()
    return result, time.monotonic() - start


# -- probe 3: a VAL error reply to the idle pose poll --------------------------------------------
def probe_val_error_reply_to_idle_poll(tmp_path, short_dir, backing,
                                                                 emulator):
    config = service_config(tmp_path, short_dir, service={"idle_poll_s": 0.05})
    opener = device_opener(val_arm(emulator.url), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client, \
            client_for(service) as watcher:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        emulator.set_faults(ValFaults(forced_error="Position out of range"))
        reason = next_state_event(events, "fault")["reason"]
        assert "DeviceFaultError" in reason and "Position out of range" in reason
        assert "safety" not in reason and "rejected" not in reason
        status = client.call("status")
        assert status["state"] == "fault" and status["fault"]["code"] == "device"
        emulator.set_faults(ValFaults())
        assert client.call("reset")["state"] == "idle"


# -- probes 4 and 5: abort and SIGTERM while a VAL move waits on a dropped link ----------------
def _job_waiting_on_a_dead_link(client, emulator, backing) -> dict:
    assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
    emulator.set_faults(ValFaults(drop_link_after_lines=0))  # pty: the controller falls silent
    job = client.call("acquire", set="nn1")["job"]
    # the job's first exchange is now waiting for a reply that never comes
    deadline = time.monotonic() + EVENT_TIMEOUT_S
    while client.call("status")["job"] is None and time.monotonic() < deadline:
        time.sleep(0.01)
    return job


def probe_abort_on_dropped_val_link(tmp_path, short_dir,
                                                                     backing, emulator):
    config = service_config(tmp_path, short_dir)
    arm = val_arm(emulator.url, exchange_timeout_s=2.5, move_timeout_s=HANG_S)
    with running_service(config, device_opener(arm, FakeCamera(), FakeWrenchSensor())) \
            as service, client_for(service) as client, client_for(service) as watcher:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        job = _job_waiting_on_a_dead_link(client, emulator, backing)
        time.sleep(0.2)  # well inside the exchange
        answer, seconds = timed(lambda: client.call("abort"))
        assert seconds < BOUND_S, f"abort took {seconds:.1f} s"
        assert answer["aborted"]["id"] == job["id"] and not answer["halted"]
        assert "no reply to the halt" in answer["halt_error"]
        assert "TypeError" not in json.dumps(answer)
        for event in events:  # the halt's own outcome, once its exchange timed out
            if event.get("event") == "halt":
                assert not event["ok"] and "DeviceTimeoutError" in event["error"]
                break
        last = None
        deadline = time.monotonic() + EVENT_TIMEOUT_S
        while last is None and time.monotonic() < deadline:
            last = client.call("status")["last_job"]
            time.sleep(0.02)
        assert last["outcome"] in ("aborted", "fault") and "TypeError" not in last["reason"]
        assert "internal error" not in last["reason"]
        emulator.set_faults(ValFaults())
        if client.call("status")["state"] == "fault":
            assert client.call("reset")["state"] == "idle"
        assert client.call("status")["state"] == "idle"


def probe_stop_on_dropped_val_link(tmp_path, short_dir, backing,
                                                            emulator):
    config = service_config(tmp_path, short_dir, service={"stop_timeout_s": 1.0})
    arm = val_arm(emulator.url, exchange_timeout_s=HANG_S, move_timeout_s=HANG_S)
    service = Service(config, opener=device_opener(arm, FakeCamera(), FakeWrenchSensor()))
    thread = threading.Thread(target=service.run)
    thread.start()
    try:
        assert service.serving.wait(START_TIMEOUT_S)
        with client_for(service) as client:
            _job_waiting_on_a_dead_link(client, emulator, backing)
            time.sleep(0.2)
    finally:
        _, seconds = timed(lambda: (service.stop(), thread.join(HANG_S)))
    assert not thread.is_alive()
    assert seconds < 1.0 + 1.5, f"stop took {seconds:.1f} s with stop_timeout_s 1"


def probe_stop_with_silent_stream_clients(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir, service={"stop_timeout_s": 1.0})
    service = Service(config, opener=device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor()))
    thread = threading.Thread(target=service.run)
    thread.start()
    silent = []
    try:
        assert service.serving.wait(START_TIMEOUT_S)
        for _ in range(10):
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect(str(service.socket_path))
            sock.sendall(b'{"cmd":"stream"}\n')
            silent.append(sock)
        deadline = time.monotonic() + EVENT_TIMEOUT_S
        while client_count(service) < 10 and time.monotonic() < deadline:
            time.sleep(0.01)
        big = {"event": "test", "padding": "x" * 16384}
        for _ in range(400):  # far more than the clients' socket buffers hold
            service._hub.publish(big)
        time.sleep(0.3)
    finally:
        _, seconds = timed(lambda: (service.stop(), thread.join(HANG_S)))
        for sock in silent:
            sock.close()
    assert not thread.is_alive()
    assert seconds < 1.0 + 1.5, f"stop took {seconds:.1f} s with 10 silent stream clients"


def client_count(service: Service) -> int:
    with client_for(service) as client:
        return client.call("status")["clients"] - 1


# -- probes 6 and 7: real signals to `finepos serve` ----------------------------------------------
def _serve(config: Path, log: Path) -> subprocess.Popen:
    command = [sys.executable, "-m", "controller.cli", "serve", "--config", str(config)]
    return subprocess.Popen(command, cwd=REPO, stdout=log.open("wb"), stderr=subprocess.STDOUT)


def _wait_for_socket(path: Path, process: subprocess.Popen) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S * 2
    while time.monotonic() < deadline:
        assert process.poll() is None, "finepos serve exited early"
        if path.exists():
            try:
                with ServiceClient(path, timeout_s=EVENT_TIMEOUT_S) as client:
                    if client.call("status")["state"] in ("idle", "fault"):
                        return
            except OSError:
                pass
        time.sleep(0.1)
    raise AssertionError("finepos serve did not start")


def _config(work: Path) -> dict:
    return {"controller": {"paths": {"state_dir": str(work / "state"),
                                     "log_dir": str(work / "log")}},
            "service": {"socket_path": str(work / "fp.sock"), "idle_poll_s": 0.0}}


def probe_non_utf8_config_sighup_and_start(short_dir):
    config = short_dir / "finepos.yaml"
    config.write_text(yaml.safe_dump(_config(short_dir)))
    process = _serve(config, short_dir / "serve.log")
    try:
        _wait_for_socket(short_dir / "fp.sock", process)
        config.write_bytes(config.read_bytes() + b"# \xff\xfe bad\n")
        process.send_signal(1)  # SIGHUP
        deadline = time.monotonic() + EVENT_TIMEOUT_S
        reload = None
        while reload is None and time.monotonic() < deadline:
            with ServiceClient(short_dir / "fp.sock", timeout_s=EVENT_TIMEOUT_S) as client:
                reload = client.call("status")["config"]["last_reload"]
            time.sleep(0.05)
        assert reload is not None and not reload["ok"] and "UTF-8" in reload["message"]
        assert process.poll() is None
    finally:
        process.terminate()
        assert process.wait(START_TIMEOUT_S) == 0
    log = (short_dir / "serve.log").read_text()
    assert "Traceback" not in log
    again = subprocess.run([sys.executable, "-m", "controller.cli", "serve", "--config",
                            str(config)], cwd=REPO, capture_output=True, text=True,
                           timeout=START_TIMEOUT_S * 2)
    assert again.returncode == 2, again.stderr
    assert "Traceback" not in again.stderr
    (line,) = [line for line in again.stderr.splitlines() if line.startswith("finepos:")]
    assert "not UTF-8" in line and str(config) in line, line


def probe_sigterm_during_train(short_dir):
    data = _config(short_dir)
    data["controller"]["acquisition"] = {"nn1": {"shape": [2, 2, 2]},
                                         "nn2": {"shape": [2, 2, 2]}, "test_count": 4}
    config = short_dir / "finepos.yaml"
    config.write_text(yaml.safe_dump(data))
    sock = short_dir / "fp.sock"
    outcomes = []
    for run in range(3):
        process = _serve(config, short_dir / f"serve-{run}.log")
        try:
            _wait_for_socket(sock, process)
            with ServiceClient(sock, timeout_s=None) as client:
                if run == 0:
                    client.call("teach", auto=True, wait=True, timeout_s=None)
                    for name in ("nn1", "nn2"):
                        client.call("acquire", set=name, wait=True, timeout_s=None)
                    assert client.call("train", wait=True, timeout_s=None)["job"][
                        "outcome"] == "done"
                    model = client.call("status")["model"]["file"]
                    before = Path(model).read_bytes()
                client.call("train")
            time.sleep(0.2)
            process.terminate()
            outcomes.append(process.wait(START_TIMEOUT_S))
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        log = (short_dir / f"serve-{run}.log").read_text()
        assert outcomes[-1] == 0, log[-3000:]
        assert "Traceback" not in log and "terminate called" not in log
        after = Path(model).read_bytes()  # the old file, or the whole new one renamed over it
        assert after == before or ModelBundle.load(model)
        before = after


# -- probe 1: numbers too big for a float --------------------------------------------------------
HUGE = "1" + "0" * 400
OVERFLOWING = tuple(template.replace("HUGE", HUGE) for template in (
    '{"cmd":"position","args":{"max_loops":HUGE}}',
    '{"cmd":"position","args":{"offset":[HUGE,0,0]}}',
    '{"cmd":"position","args":{"offset":[0,0,-HUGE]}}',
    '{"cmd":"acquire","args":{"set":"nn1","seed":HUGE}}',
    '{"cmd":"teach","args":{"grasp_depth_mm":HUGE}}',
    '{"cmd":"status","id":HUGE}',
))


def probe_number_too_big_for_a_float(
        tmp_path, short_dir, line):
    config = service_config(tmp_path, short_dir)
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, \
            socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(EVENT_TIMEOUT_S)
        sock.connect(str(service.socket_path))
        stream = sock.makefile("rb")
        sock.sendall(line.encode() + b"\n")
        answer = json.loads(stream.readline())
        assert not answer["ok"] and answer["error"]["code"] == "bad_request", answer
        sock.sendall(b'{"cmd":"status","id":2}\n')
        assert json.loads(stream.readline())["result"]["state"] == "idle"


# -- probe 2: unauthenticated TCP peers must not starve authorised ones --------------------------
def probe_trickling_tcp_peers(tmp_path, short_dir, monkeypatch):
    from controller.service import connection

    monkeypatch.setattr(connection, "AUTH_TIMEOUT_S", 1.0)
    tokens, port = token_file(tmp_path), free_port()
    config = service_config(tmp_path, short_dir, service={
        "max_clients": 4, "tcp": {"port": port, "token_file": str(tokens)}})
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    hostile = []
    with running_service(config, opener) as service:
        try:
            for _ in range(40):
                sock = socket.create_connection(("127.0.0.1", port))
                sock.sendall(b"{")
                hostile.append(sock)
            for _ in range(3):  # a byte now and then: the deadline is not extended
                time.sleep(0.4)
                for sock in hostile:
                    try:
                        sock.sendall(b" ")
                    except OSError:
                        pass
                with client_for(service) as operator:
                    assert operator.call("status")["state"] == "idle"
                    assert operator.call("abort")["halted"]
            for sock in hostile:  # every trickling peer is cut off (refused, or at its deadline)
                sock.settimeout(EVENT_TIMEOUT_S)
                with contextlib.suppress(ConnectionResetError):
                    while sock.recv(4096):
                        pass
        finally:
            for sock in hostile:
                sock.close()


# -- probe 8: a full disk under the iteration log ------------------------------------------------
@pytest.fixture
def tiny_disk(tmp_path):
    """A 200 KB tmpfs (root only; skipped otherwise), unmounted afterwards."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    folder = tmp_path / "tiny"
    folder.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(folder)],
                   check=True)
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def _fill(folder: Path) -> Path:
    """Fill the file system of ``folder``; returns the filler file (delete it to free space)."""
    filler = folder / "filler"
    with open(filler, "wb", buffering=0) as f, contextlib.suppress(OSError):
        while True:
            f.write(b"\0" * 1024)
    return filler


RECORD = {"run_id": "r", "iteration": 1, "error": [0.5, -0.25, 1.0], "pad": "x" * 900}


def test_full_disk_leaves_the_log_parseable_and_it_resumes(tiny_disk):
    log_path = tiny_disk / "iterations.jsonl"
    with IterationLog(log_path) as log:
        log.write(RECORD)
        filler = _fill(tiny_disk)
        with pytest.raises(LogWriteError) as full:
            for i in range(200):
                log.write({**RECORD, "iteration": i})
        assert full.value.disk_full and "disk_full" in str(full.value)
        assert not log.has_room()
        read_log(log_path)  # every line whole
        filler.unlink()
        assert log.has_room()
        log.write({**RECORD, "iteration": 999})
    records = read_log(log_path)
    assert records[-1]["iteration"] == 999


def test_a_half_record_left_by_a_kill_is_removed_at_open(tmp_path):
    log_path = tmp_path / "iterations.jsonl"
    with IterationLog(log_path) as log:
        log.write(RECORD)
    with open(log_path, "ab") as f:  # what kill -9 in the middle of a write leaves
        f.write(b'{"run_id":"r","iterat')
    with IterationLog(log_path) as log:
        log.write({**RECORD, "iteration": 2})
    assert [r["iteration"] for r in read_log(log_path)] == [1, 2]
    records, damaged = scan_log(log_path)
    assert len(records) == 2 and damaged == 0


def test_readers_skip_and_count_damaged_lines(tmp_path):
    log_path = tmp_path / "iterations.jsonl"
    log_path.write_bytes(b'{"iteration":1}\n{"iter\n\xff\xfe\n[1]\n{"iteration":2}\n')
    records, damaged = scan_log(log_path)
    assert [r["iteration"] for r in records] == [1, 2] and damaged == 3


def test_the_log_refuses_a_symlink(tmp_path):
    target = tmp_path / "elsewhere"
    target.write_text("")
    (tmp_path / "iterations.jsonl").symlink_to(target)
    with pytest.raises(LogWriteError, match="symlink"):
        IterationLog(tmp_path / "iterations.jsonl")
    assert target.read_text() == ""


def probe_disk_full_under_the_log(tmp_path, short_dir, tiny_disk,
                                                               cube_model_files):
    config = service_config(tmp_path, short_dir, controller={
        "paths": {"state_dir": str(tmp_path / "state"), "log_dir": str(tiny_disk)},
        "loop": {"converge_mm": 0.0, "converge_deg": 0.0}})
    copy_state(cube_model_files, config)
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-8.0, 6.0, 0.0, -12.0)))
    with running_service(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                               FakeWrenchSensor())) \
            as service, client_for(service) as client:
        filler = _fill(tiny_disk)
        job = client.call("position", wait=True, max_loops=3)["job"]
        assert job["outcome"] == "fault" and "internal error" not in job["reason"], job
        status = client.call("status")
        assert status["state"] == "fault" and status["fault"]["code"] == "disk_full", status
        filler.unlink()
        wait_for_state(service, "idle")
        job = client.call("position", wait=True, max_loops=1)["job"]
        assert "disk" not in job["reason"], job
    read_log(tiny_disk / "iterations.jsonl")


# -- probe 9: a damaged cell.json through the service --------------------------------------------
def probe_damaged_cell_state(tmp_path, short_dir,
                                                                    damage):
    config = service_config(tmp_path, short_dir)
    state_dir = Path(config.controller.paths.state_dir)
    state_dir.mkdir(parents=True)
    text = json.dumps({"version": 1, "nominal_pose": {"x_mm": 0.5, "y_mm": 0, "z_mm": 150,
                                                      "o_deg": -90, "a_deg": 90, "t_deg": 0},
                       "object_kind": "cube", "kappa": 4, "grasp_depth_mm": 5,
                       "object_width_mm": 30, "source": "test", "taught_at": 1.0})
    if damage == "NOMINAL_STRING":
        text = json.dumps({**json.loads(text), "nominal_pose": "300,0,150,-90,90,0"})
    else:
        text = text.replace('"x_mm": 0.5', damage)
    (state_dir / "cell.json").write_text(text)
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client:
        job = client.call("acquire", set="nn1", wait=True)["job"]
        assert job["outcome"] == "failed" and "StateError" in job["reason"], job
        assert "cell.json" in job["reason"] and "internal error" not in job["reason"]
        assert client.call("status")["state"] == "idle"


def probe_dataset_on_a_full_disk(tmp_path, short_dir, tiny_disk):
    config = service_config(tmp_path, short_dir, controller={
        "paths": {"state_dir": str(tiny_disk), "log_dir": str(tmp_path / "log")}})
    opener = device_opener(FakeArm(object_width_mm=30.0), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client:
        assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
        filler = _fill(tiny_disk)
        job = client.call("acquire", set="nn1", wait=True)["job"]
        assert job["outcome"] == "fault" and job["reason"].startswith("disk_full"), job
        assert client.call("status")["fault"]["code"] == "disk_full"
        assert not list(tiny_disk.glob(".*.tmp")) and not (tiny_disk / "datasets" / "nn1.npz"
                                                            ).exists()
        filler.unlink()
        wait_for_state(service, "idle")
        assert client.call("acquire", set="nn1", wait=True)["job"]["outcome"] == "done"


# -- probe 10: damaged labels, a model that is a FIFO or /dev/zero -------------------------------
def probe_labels_of_1e308_fail_train(tmp_path, short_dir, cube_model_files):
    config = service_config(tmp_path, short_dir)
    state = copy_state(cube_model_files, config)
    (state / "datasets").mkdir()
    np.savez(state / "datasets" / "nn1.npz", labels=np.array([[1e308, 0.0, 0.0]]),
             metadata_json=np.frombuffer(json.dumps({"format": "finepos-dataset",
                                                     "version": 1}).encode(), dtype=np.uint8))
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client:
        job = client.call("train", wait=True)["job"]
        assert job["outcome"] == "failed" and "nn1.npz" in job["reason"], job
        assert "internal error" not in job["reason"]
        assert client.call("status")["state"] == "idle"


def probe_model_is_a_fifo_or_dev_zero(tmp_path, short_dir, cube_model_files, special):
    config = service_config(tmp_path, short_dir)
    state = copy_state(cube_model_files, config)
    model = state / "model-gabor.fpm"
    model.unlink()
    if special == "fifo":
        os.mkfifo(model)
    else:
        model.symlink_to("/dev/zero")
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client:
        with pytest.raises(ServiceError) as refused:  # answered at once, not after a hang
            client.call("reload", system="gabor")
        assert refused.value.code == "failed" and str(model) in refused.value.message
        assert client.call("status")["state"] == "idle"


# -- probe 11: stale temporary files, a symlink as the iteration log -----------------------------
def probe_stale_temp_files_are_removed_at_start(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir)
    state = Path(config.controller.paths.state_dir)
    (state / "datasets").mkdir(parents=True)
    stale = [state / ".model-gabor.fpm.k2j3.tmp", state / "datasets" / ".nn1.npz.x8y.tmp"]
    for path in stale:
        path.write_bytes(b"\0" * 100_000)
    opener = device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client:
        assert client.call("status")["state"] == "idle"
    assert not any(path.exists() for path in stale)


def probe_iteration_log_symlink_is_refused(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir)
    log_dir = Path(config.controller.paths.log_dir)
    log_dir.mkdir(parents=True)
    target = tmp_path / "elsewhere.txt"
    target.write_text("precious\n")
    (log_dir / "iterations.jsonl").symlink_to(target)
    service = Service(config, opener=device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor()))
    with pytest.raises(LogWriteError, match="symlink"):
        service.run()
    assert target.read_text() == "precious\n"


# -- the matrix: every probe of issue 15 as one parametrised case --------------------------------
SLOW = pytest.mark.slow
MATRIX = [
    pytest.param(probe_number_too_big_for_a_float, {"line": line}, id=f"1-huge-number-{i}")
    for i, line in enumerate(OVERFLOWING)
] + [
    pytest.param(probe_trickling_tcp_peers, {}, id="2-trickling-tcp-peers"),
    pytest.param(probe_val_error_reply_to_idle_poll, {}, id="3-val-error-to-idle-poll"),
    pytest.param(probe_abort_on_dropped_val_link, {}, id="4-abort-on-dropped-val-link"),
    pytest.param(probe_stop_on_dropped_val_link, {}, id="5-stop-on-dropped-val-link"),
    pytest.param(probe_stop_with_silent_stream_clients, {}, id="5-stop-with-silent-streams"),
    pytest.param(probe_sigterm_during_train, {}, id="6-sigterm-during-train", marks=SLOW),
    pytest.param(probe_non_utf8_config_sighup_and_start, {}, id="7-non-utf8-config",
                 marks=SLOW),
    pytest.param(probe_disk_full_under_the_log, {}, id="8-disk-full-log"),
    pytest.param(probe_dataset_on_a_full_disk, {}, id="8-disk-full-dataset"),
] + [
    pytest.param(probe_damaged_cell_state, {"damage": damage}, id=f"9-cell-state-{name}")
    for name, damage in (("nan", '"x_mm": NaN'), ("inf", '"x_mm": 1e999'),
                         ("huge", '"x_mm": 1e308'), ("string", "NOMINAL_STRING"))
] + [
    pytest.param(probe_labels_of_1e308_fail_train, {}, id="10-labels-1e308"),
    pytest.param(probe_model_is_a_fifo_or_dev_zero, {"special": "fifo"}, id="10-model-fifo"),
    pytest.param(probe_model_is_a_fifo_or_dev_zero, {"special": "zero"},
                 id="10-model-dev-zero"),
    pytest.param(probe_stale_temp_files_are_removed_at_start, {}, id="11-stale-tmp-files"),
    pytest.param(probe_iteration_log_symlink_is_refused, {}, id="11-log-symlink"),
]
# Probe 10's config size limits: tests/drivers/core/test_typed_config.py; the file-level
# checks: tests/calibration_free/test_model_file.py, tests/drivers/core/test_files.py.


@pytest.mark.parametrize(("probe", "given"), MATRIX)
def test_fault_matrix(request, probe, given):
    """Run one probe with its fixtures (by parameter name) and its given arguments."""
    names = inspect.signature(probe).parameters
    kwargs = {name: given[name] if name in given else request.getfixturevalue(name)
              for name in names}
    probe(**kwargs)
