"""Fixtures of the service tests: an in-process service on injected devices, short socket paths,
a notify socket standing in for systemd, and a small trained model for a cube cell."""

from __future__ import annotations

import contextlib
import os
import selectors
import shutil
import socket
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from calibration_free.dataset import grid_offsets, staggered_grid_offsets
from calibration_free.synthetic import SyntheticCell, render, render_dataset
from calibration_free.training import TrainingSettings, train_bundle
from controller.config import config_from_mapping
from controller.devices import CellDevices
from controller.service.client import ServiceClient
from controller.service.sd_notify import Notifier
from controller.service.service import Service
from drivers.core.cell_state import CellState
from drivers.core.pose import Pose
from sim_backend.emulators.val.server import ValEmulator
from tests.mocks.fakes import FakeArm

START_TIMEOUT_S = 30.0  # bounds only; no assertion depends on how long anything takes
EVENT_TIMEOUT_S = 20.0
NOMINAL = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)


@pytest.fixture
def short_dir() -> Iterator[Path]:
    """A folder with a short path (AF_UNIX paths are limited to 107 bytes)."""
    path = Path(tempfile.mkdtemp(prefix="fp-", dir="/tmp"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def backing():
    """A fake arm behind the VAL emulator (``emulator``)."""
    with FakeArm(object_width_mm=30.0) as arm:
        yield arm


@pytest.fixture
def emulator(backing):
    """The VAL emulator serving ``backing`` on a pty."""
    with ValEmulator(backing) as emu:
        yield emu


def cube_view(arm, knock_mm: float = 0.0) -> Callable[[], np.ndarray]:
    """A FakeCamera source: the synthetic cube as the hand camera sees it from ``arm``'s pose
    (taught at NOMINAL); ``knock_mm`` shifts the view as a knocked camera would."""
    scene = SyntheticCell()

    def view() -> np.ndarray:
        step = arm._pose.tool_step_to(NOMINAL)
        return render(scene, np.array([step.dx_mm + knock_mm, step.dy_mm, step.dphi_deg]))

    return view


def service_config(tmp_path: Path, socket_dir: Path, **sections):
    """A config whose files live under ``tmp_path``; ``sections`` are merged over it."""
    data = {
        "controller": {"paths": {"state_dir": str(tmp_path / "state"),
                                 "log_dir": str(tmp_path / "log")},
                       "acquisition": {"nn1": {"shape": [2, 2, 2]}, "nn2": {"shape": [2, 2, 2]},
                                       "test_count": 4},
                       # The fakes have no part to weigh; their gripper reports the width.
                       "grasp": {"check": "width"}},
        "service": {"socket_path": str(socket_dir / "fp.sock"), "idle_poll_s": 0.0,
                    "reconnect_initial_s": 0.05, "reconnect_max_s": 0.2,
                    "stop_timeout_s": 1.0},
    }
    for name, values in sections.items():
        data[name] = {**data.get(name, {}), **values}
    return config_from_mapping(data, "<test>")


TOKEN = "s3cret-token-0123456789"  # the TCP control token the tests' services accept


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def token_file(tmp_path: Path) -> Path:
    """A token file holding ``TOKEN``, readable by its owner only (as the service asks)."""
    path = tmp_path / "token"
    path.write_text(f"{TOKEN}\n")
    path.chmod(0o600)
    return path


def device_opener(arm, camera, wrench, cell=None) -> Callable:
    """An opener (like controller.devices.open_devices) serving these device objects."""

    @contextlib.contextmanager
    def opener(config):
        with contextlib.ExitStack() as stack:
            for device in (arm, camera, wrench):
                stack.callback(device.disconnect)
                device.connect()
                device.activate()
            yield CellDevices(arm, camera, wrench, cell)

    return opener


@contextlib.contextmanager
def running_service(config, opener, notifier: Notifier | None = None) -> Iterator[Service]:
    """The service's control loop in a thread; stopped (as by SIGTERM) on exit."""
    service = Service(config, opener=opener, notifier=notifier)
    errors: list[BaseException] = []

    def run() -> None:
        try:
            service.run()
        except BaseException as exc:  # reported to the test below
            errors.append(exc)
            service.serving.set()

    thread = threading.Thread(target=run, name="service-under-test")
    thread.start()
    try:
        assert service.serving.wait(START_TIMEOUT_S), "the service did not start serving"
        assert not errors, f"the service failed to start: {errors[0]!r}"
        yield service
    finally:
        service.stop()
        thread.join(START_TIMEOUT_S)
        assert not thread.is_alive(), "the service did not stop"
    assert not errors, f"the service failed: {errors[0]!r}"


def client_for(service: Service) -> ServiceClient:
    return ServiceClient(service.socket_path, timeout_s=EVENT_TIMEOUT_S)


def next_state_event(events: Iterator[dict], state: str) -> dict:
    """The next state event reaching ``state`` (the stream's socket timeout bounds the wait)."""
    for event in events:
        if event.get("event") == "state" and event["state"] == state:
            return event
    raise AssertionError(f"stream ended before state {state}")


def wait_for_state(service: Service, state: str) -> None:
    """Return once the service is in ``state`` (subscribing first, so no change is missed)."""
    with client_for(service) as watcher, client_for(service) as probe:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        if probe.call("status")["state"] != state:
            next_state_event(events, state)


class NotifySocket:
    """A datagram socket standing in for systemd's NOTIFY_SOCKET. A reader thread keeps it
    drained, as systemd does (the service drops notifications a full socket cannot take)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.messages: list[str] = []
        self._seen = 0  # messages before this index were returned by wait_for/drain
        self._arrived = threading.Condition()
        self._wake_r, self._wake_w = os.pipe()
        self._reader = threading.Thread(target=self._receive, name="notify-reader", daemon=True)
        self._reader.start()

    def _receive(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self.sock, selectors.EVENT_READ)
            selector.register(self._wake_r, selectors.EVENT_READ)
            while True:
                for key, _ in selector.select():
                    if key.fileobj == self._wake_r:
                        return
                    message = self.sock.recv(65536).decode()
                    with self._arrived:
                        self.messages.append(message)
                        self._arrived.notify_all()

    def close(self) -> None:
        os.write(self._wake_w, b"x")
        self._reader.join()
        for fd in (self._wake_r, self._wake_w):
            os.close(fd)
        self.sock.close()

    def drain(self) -> list[str]:
        """The messages that arrived since the last wait_for/drain."""
        with self._arrived:
            new, self._seen = self.messages[self._seen:], len(self.messages)
        return new

    def wait_for(self, predicate: Callable[[str], bool], timeout_s: float = EVENT_TIMEOUT_S) \
            -> str:
        """The first message since the last wait_for/drain that satisfies ``predicate``."""

        def found() -> int | None:
            return next((i for i in range(self._seen, len(self.messages))
                         if predicate(self.messages[i])), None)

        with self._arrived:
            if not self._arrived.wait_for(lambda: found() is not None, timeout_s):
                raise AssertionError(f"no matching datagram within {timeout_s} s; got "
                                     f"{self.messages[self._seen:]}")
            index = found()
            self._seen = index + 1
            return self.messages[index]


@pytest.fixture
def notify_socket(short_dir) -> Iterator[NotifySocket]:
    notify = NotifySocket(short_dir / "notify")
    yield notify
    notify.close()


@pytest.fixture(scope="session")
def cube_model_files(tmp_path_factory) -> Path:
    """A state folder with a cube teach-in (cell.json) and a quickly trained gabor model."""
    folder = tmp_path_factory.mktemp("cube-model")
    cell, rng = SyntheticCell(), np.random.default_rng(0)
    nn1 = render_dataset(cell, grid_offsets(25.0, 45.0, (3, 3, 7)), rng)
    nn2 = render_dataset(cell, staggered_grid_offsets(5.0, 45.0, (3, 3, 7)), rng)
    bundle = train_bundle(nn1, nn2, object_kind="cube", kappa=4,
                          nominal_pose=NOMINAL.as_dict(),
                          settings=TrainingSettings(nn1_epochs=50, nn2_epochs=50))
    bundle.save(folder / "model-gabor.fpm")
    CellState(NOMINAL, "cube", 4, 5.0, 30.0, "test", 0.0).save(folder / "cell.json")
    return folder


@pytest.fixture(scope="session")
def two_part_model_files(tmp_path_factory, cube_model_files) -> Path:
    """A state folder with two parts in their own folders: ``cube/`` (``cube_model_files``)
    and ``nut/``, taught at the same pose on the same synthetic view (a fake cell shows one
    part for both) with a model of its own (kappa 6: grid angles within +/-30 deg)."""
    folder = tmp_path_factory.mktemp("two-parts")
    shutil.copytree(cube_model_files, folder / "cube")
    cell, rng = SyntheticCell(), np.random.default_rng(1)
    nn1 = render_dataset(cell, grid_offsets(25.0, 30.0, (3, 3, 7)), rng)
    nn2 = render_dataset(cell, staggered_grid_offsets(5.0, 30.0, (3, 3, 7)), rng)
    bundle = train_bundle(nn1, nn2, object_kind="nut", kappa=6,
                          nominal_pose=NOMINAL.as_dict(),
                          settings=TrainingSettings(nn1_epochs=50, nn2_epochs=50))
    (folder / "nut").mkdir()
    bundle.save(folder / "nut" / "model-gabor.fpm")
    CellState(NOMINAL, "nut", 6, 5.0, 24.0, "test", 0.0).save(folder / "nut" / "cell.json")
    return folder


def copy_state(source: Path, config) -> Path:
    target = Path(config.controller.paths.state_dir)
    shutil.copytree(source, target)
    return target

