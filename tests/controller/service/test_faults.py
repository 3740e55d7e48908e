"""Faults through the real drivers and their emulators: the VAL arm's serial link dropping mid-move,
returning garbage or timing out; the MJPEG camera stalling; the ATI sensor flagging an overload.
Each ends in fault with a clear reason, refuses further motion, and recovers by reset once the
cause is gone. Also: a force guard tripping, a lost object, an abort, an idle link check."""

from __future__ import annotations

import contextlib
import threading
from pathlib import Path

import numpy as np
import pytest

from calibration_free.bundle import ModelBundle
from calibration_free.synthetic import SyntheticCell, render
from controller.devices import open_devices
from controller.loop.iteration_log import read_log
from controller.loop.positioning import LoopConfig
from controller.recipe import Recipe, with_recipe_stored
from controller.service.client import ServiceError
from controller.service.sd_notify import Notifier
from drivers.camera.mjpeg_server import MjpegServer
from drivers.core.pose import ToolStep
from drivers.interfaces import Wrench
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.ati.emulator import AtiEmulator
from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    NOMINAL,
    client_for,
    copy_state,
    device_opener,
    next_state_event,
    running_service,
    service_config,
    wait_for_state,
)
from tests.mocks.fakes import HOME, FakeArm, FakeCamera, FakeWrenchSensor

LIMITS = SafetyLimits()  # as in the service config, which plans its transfers with them
LINK_TIMEOUT_S = 0.5  # the drivers' timeouts: short, so each injected fault costs little
TEACH = {"grasp_depth_mm": 5.0, "object_width_mm": 30.0}
MOTION_COMMANDS = (("acquire", {"set": "nn1"}), ("position", {}), ("grasp", {}),
                   ("teach", TEACH))


def assert_motion_refused(client, arm: FakeArm) -> None:
    moves = len(arm.moves)
    for cmd, args in MOTION_COMMANDS:
        with pytest.raises(ServiceError) as refused:
            client.call(cmd, **args)
        assert refused.value.code == "fault" and "refused" in refused.value.message
    assert len(arm.moves) == moves


def val_arm(url: str) -> ValArm:
    return ValArm(ValConfig(port=url, exchange_timeout_s=LINK_TIMEOUT_S,
                            move_timeout_s=LINK_TIMEOUT_S), LIMITS)


FAULTS = {
    "link drop mid-move": (ValFaults(drop_link_after_lines=7), "DeviceTimeoutError"),
    "garbage": (ValFaults(garbage=DEFAULT_GARBAGE), "ProtocolError"),
    "timeout": (ValFaults(reply_delay_s=3 * LINK_TIMEOUT_S), "DeviceTimeoutError"),
}


@pytest.mark.parametrize("fault", FAULTS, ids=list(FAULTS))
def test_val_link_fault_refuses_motion_until_reset(tmp_path, short_dir, backing, emulator,
                                                   fault):
    faults, error = FAULTS[fault]
    config = service_config(tmp_path, short_dir)
    opener = device_opener(val_arm(emulator.url), FakeCamera(), FakeWrenchSensor())
    with running_service(config, opener) as service, client_for(service) as client, \
            client_for(service) as watcher:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
        emulator.set_faults(faults)
        job = client.call("acquire", timeout_s=None, set="nn1", wait=True)["job"]
        assert job["outcome"] == "fault" and error in job["reason"], job
        assert next_state_event(events, "fault")["reason"].startswith("acquire job 2: device")
        status = client.call("status")
        assert status["state"] == "fault" and "arm" in status["fault"]["devices"]
        assert_motion_refused(client, backing)
        if fault == "garbage":  # the cause is still there: reset is refused
            with pytest.raises(ServiceError, match="reset failed.*still in fault"):
                client.call("reset")
        emulator.set_faults(ValFaults())
        assert client.call("reset")["state"] == "idle"
        assert next_state_event(events, "idle")["reason"] == "reset"
        moves = len(backing.moves)
        assert client.call("acquire", timeout_s=None, set="nn1", wait=True)["job"][
            "outcome"] == "done"
        assert len(backing.moves) > moves


@contextlib.contextmanager
def _link_dropped_while_idle(tmp_path, short_dir, backing, notify_socket):
    """A service on the VAL emulator over TCP, polling the idle arm every 50 ms, whose link
    then closes every connection: yields the emulator and a client."""
    config = service_config(tmp_path, short_dir, service={"idle_poll_s": 0.05})
    notifier = Notifier({"NOTIFY_SOCKET": str(notify_socket.path)})
    try:
        with ValEmulator(backing, tcp_port=0) as emulator, \
                running_service(config, device_opener(val_arm(emulator.url), FakeCamera(),
                                                      FakeWrenchSensor()), notifier) as service, \
                client_for(service) as client:
            emulator.set_faults(ValFaults(drop_link_after_lines=0))  # every connection closed
            yield emulator, client
    finally:
        notifier.close()


def test_lost_link_while_idle_is_noticed_and_reconnected_with_backoff(
        tmp_path, short_dir, backing, notify_socket):
    with _link_dropped_while_idle(tmp_path, short_dir, backing, notify_socket) as (
            emulator, client):
        notify_socket.wait_for(lambda m: m.startswith("STATUS=fault: arm check while idle"))
        notify_socket.wait_for(lambda m: "reconnect attempt" in m)
        emulator.set_faults(ValFaults())
        notify_socket.wait_for(lambda m: "devices reconnected" in m)
        fault = client.call("status")["fault"]
        assert fault["reconnected"] and fault["reconnect_attempts"] >= 2
        assert client.call("status")["state"] == "fault", "resuming needs a reset"
        assert client.call("reset")["state"] == "idle"


def test_abort_with_the_arm_disconnected_says_no_halt_reached_it(tmp_path, short_dir, backing,
                                                                  notify_socket):
    with _link_dropped_while_idle(tmp_path, short_dir, backing, notify_socket) as (
            emulator, client):
        notify_socket.wait_for(lambda m: "reconnect attempt" in m)  # its connect failed
        assert client.call("status")["fault"]["devices"]["arm"] == "disconnected"
        answer = client.call("abort")
        assert answer["halted"] is False and "disconnected" in answer["halt_error"]
        assert "teach pendant" in answer["action"]


@pytest.fixture
def emulated_hardware(backing):
    """The VAL, ATI and MJPEG emulators over fakes, and the config sections that select the
    real drivers for them (opened by controller.devices.open_devices, as in production)."""
    with ValEmulator(backing) as val, FakeWrenchSensor() as load, AtiEmulator(load) as ati, \
            FakeCamera() as source, MjpegServer(source, fps=30) as stream:
        sections = {
            "arm": {"type": "val", "port": val.url, "exchange_timeout_s": LINK_TIMEOUT_S,
                    "move_timeout_s": LINK_TIMEOUT_S,
                    "gripper_closed_width_mm": TEACH["object_width_mm"]},  # VAL: no feedback
            "camera": {"type": "opencv", "source": stream.stream_url,
                       "timeout_s": LINK_TIMEOUT_S},
            "wrench": {"type": "ati", "port": ati.url, "timeout_s": LINK_TIMEOUT_S},
        }
        yield sections, ati, stream


def test_camera_stall_faults_with_the_reason_until_reset(tmp_path, short_dir, backing,
                                                         emulated_hardware):
    sections, _, stream = emulated_hardware
    config = service_config(tmp_path, short_dir, **sections)
    with running_service(config, open_devices) as service, client_for(service) as client:
        client.call("teach", wait=True, **TEACH)
        stream.paused.set()
        job = client.call("acquire", timeout_s=None, set="nn1", wait=True)["job"]
        assert job["outcome"] == "fault"
        assert f"no frame within {LINK_TIMEOUT_S} s" in job["reason"]
        assert client.call("status")["fault"]["devices"].keys() == {"camera"}
        assert_motion_refused(client, backing)
        stream.paused.clear()
        assert client.call("reset")["state"] == "idle"
        assert client.call("acquire", timeout_s=None, set="nn1", wait=True)["job"][
            "outcome"] == "done"


def test_wrench_sensor_overload_faults_with_the_status_word(tmp_path, short_dir, backing,
                                                            emulated_hardware):
    sections, ati, _ = emulated_hardware
    config = service_config(tmp_path, short_dir, **sections)
    with running_service(config, open_devices) as service, client_for(service) as client:
        client.call("teach", wait=True, **TEACH)
        assert client.call("grasp", wait=True)["job"]["outcome"] == "done"
        ati.faults.status_word = 0x24
        job = client.call("grasp", wait=True)["job"]
        assert job["outcome"] == "fault" and "status word 36 (0x24)" in job["reason"]
        assert client.call("status")["fault"]["devices"].keys() == {"wrench"}
        assert_motion_refused(client, backing)
        ati.faults.status_word = 0
        assert client.call("reset")["state"] == "idle"
        assert client.call("grasp", wait=True)["job"]["outcome"] == "done"


def test_force_guard_ends_the_grasp_with_its_reason_and_the_service_stays_usable(
        tmp_path, short_dir):
    config = service_config(tmp_path, short_dir)
    arm = FakeArm(object_width_mm=30.0)

    def pressing() -> Wrench:  # 20 N per mm below the start height: over 15 N at the first mm
        return Wrench(0.0, 0.0, -20.0 * max(0.0, HOME.z_mm - arm._pose.z_mm), 0.0, 0.0, 0.0)

    with running_service(config, device_opener(arm, FakeCamera(),
                                               FakeWrenchSensor(pressing))) as service, \
            client_for(service) as client:
        client.call("teach", wait=True, **TEACH)
        job = client.call("grasp", wait=True)["job"]
        assert job["outcome"] == "failed"
        assert job["reason"].startswith("grasp failed: excessive force: force_n > 15")
        assert job["result"]["retreated"] is True
        assert client.call("status")["state"] == "idle"


def test_lost_object_is_reported_and_a_bad_model_is_refused(tmp_path, short_dir,
                                                           cube_model_files):
    config = service_config(tmp_path, short_dir)
    state_dir = copy_state(cube_model_files, config)
    with running_service(config, device_opener(FakeArm(), FakeCamera(),
                                               FakeWrenchSensor())) as service, \
            client_for(service) as client:
        model = client.call("status")["model"]
        assert model["system"] == "gabor"
        job = client.call("position", wait=True)["job"]
        assert job["outcome"] == "failed" and job["reason"].startswith("no_object: ")
        assert client.call("status")["state"] == "idle"
        (state_dir / "model-gabor.fpm").write_bytes(b"not a model")
        with pytest.raises(ServiceError, match="failed: model not loaded, the old one stays"):
            client.call("reload")
        assert client.call("status")["model"] == model


def test_camera_stall_mid_positioning_keeps_every_logged_record(tmp_path, short_dir,
                                                              cube_model_files):
    """The fake camera shows the synthetic cube where the fake arm's pose puts it, and stops
    delivering after a few frames: the records written before are all in the log, whole."""
    config = service_config(tmp_path, short_dir, controller={"loop": {
        "converge_mm": 0.0, "converge_deg": 0.0}})
    model = copy_state(cube_model_files, config) / "model-gabor.fpm"
    bundle = ModelBundle.load(model)  # a frame a look: the model's recipe
    with_recipe_stored(bundle, Recipe(loop=LoopConfig(settle_frames=1))).save(model)
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-8.0, 6.0, 0.0, -12.0)))
    scene, frames = SyntheticCell(), []

    def view() -> np.ndarray:
        frames.append(1)
        # the first look takes two frames (the exposure settles); the sixth grab gets none
        camera.stalled = len(frames) >= 5
        step = arm._pose.tool_step_to(NOMINAL)
        return render(scene, np.array([step.dx_mm, step.dy_mm, step.dphi_deg]))

    camera = FakeCamera(view)
    with running_service(config, device_opener(arm, camera, FakeWrenchSensor())) as service, \
            client_for(service) as client, client_for(service) as watcher:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        job = client.call("position", wait=True, max_loops=20)["job"]
        assert job["outcome"] == "fault" and "fake camera: no frame" in job["reason"]
        streamed = []
        for event in events:
            if event["event"] == "iteration":
                streamed.append(event["record"])
            if event["event"] == "state" and event["state"] == "fault":
                break
        log = Path(client.call("status")["iteration_log"])
    records = read_log(log)  # raises on any line that is not a whole JSON record
    assert len(records) == 4 and records == streamed
    assert [r["iteration"] for r in records] == [1, 2, 3, 4]


class GatedArm(FakeArm):
    """A fake arm whose moves wait for ``gate``; ``entered`` is set when one is waiting."""

    def __init__(self) -> None:
        super().__init__()
        self.gate = threading.Event()
        self.entered = threading.Event()

    def _move_to(self, target):
        self.entered.set()
        assert self.gate.wait(EVENT_TIMEOUT_S), "the test never opened the gate"
        return super()._move_to(target)


def test_abort_preempts_a_running_job_and_halts_the_arm(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir)
    arm = GatedArm()
    arm.gate.set()
    with running_service(config, device_opener(arm, FakeCamera(),
                                               FakeWrenchSensor())) as service, \
            client_for(service) as client:
        client.call("teach", wait=True, **TEACH)
        arm.gate.clear()
        job = client.call("acquire", set="nn1")["job"]
        assert arm.entered.wait(EVENT_TIMEOUT_S)
        moves_at_abort = len(arm.moves)
        aborted = client.call("abort")
        assert aborted["aborted"]["id"] == job["id"] and aborted["halted"] and arm.halts == 1
        arm.gate.set()
        wait_for_state(service, "idle")
        last = client.call("status")["last_job"]
        assert last["outcome"] == "aborted" and last["reason"] == "aborted by request"
        assert len(arm.moves) <= moves_at_abort + 1  # only the move already under way
        assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
        assert client.call("abort") == {"aborted": None, "halted": True, "halt_error": None}
        assert arm.halts == 2


def test_a_hung_arm_command_withholds_the_watchdog(tmp_path, short_dir, notify_socket):
    config = service_config(tmp_path, short_dir, service={"stall_timeout_s": 0.2,
                                                          "stop_timeout_s": 0.2})
    notifier = Notifier({"NOTIFY_SOCKET": str(notify_socket.path), "WATCHDOG_USEC": "100000"})
    arm = GatedArm()
    arm.gate.set()
    with running_service(config, device_opener(arm, FakeCamera(), FakeWrenchSensor()),
                         notifier) as service, client_for(service) as client:
        notify_socket.wait_for(lambda m: m == "WATCHDOG=1")
        client.call("teach", wait=True, **TEACH)
        arm.gate.clear()
        client.call("acquire", set="nn1")
        notify_socket.wait_for(lambda m: "watchdog withheld" in m)
        assert "WATCHDOG=1" not in notify_socket.drain()
        arm.gate.set()
        notify_socket.wait_for(lambda m: m == "WATCHDOG=1")
    notifier.close()
