"""The service's Prometheus metrics (``service.metrics_port``): scraped during and after a
position job and parsed with prometheus_client's own parser; the port's token on non-loopback
binds; counting from events (``controller.service.metrics``)."""

from __future__ import annotations

import socket
import urllib.error
import urllib.request

import pytest
from prometheus_client.parser import text_string_to_metric_families

from controller.config import config_from_mapping
from controller.service.listeners import ListenerError
from controller.service.metrics import ServiceMetrics
from controller.service.service import Service
from drivers.core.errors import ConfigError
from drivers.core.pose import ToolStep
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

from .conftest import (
    EVENT_TIMEOUT_S,
    TOKEN,
    client_for,
    copy_state,
    cube_view,
    device_opener,
    free_port,
    running_service,
    service_config,
    token_file,
)
from .test_faults import NOMINAL


def _samples(text: str) -> dict[tuple[str, tuple], float]:
    """{(sample name, sorted labels): value} of a scrape, read by prometheus_client's parser."""
    return {(sample.name, tuple(sorted(sample.labels.items()))): sample.value
            for family in text_string_to_metric_families(text) for sample in family.samples}


def _scrape(port: int, token: str | None = None) -> dict[tuple[str, tuple], float]:
    request = urllib.request.Request(f"http://127.0.0.1:{port}/metrics")
    if token is not None:
        request.add_header("Authorization", f"Bearer {token}")
    with urllib.request.urlopen(request, timeout=EVENT_TIMEOUT_S) as answer:
        return _samples(answer.read().decode())


def test_a_position_job_is_scraped_during_and_after_it(tmp_path, short_dir, cube_model_files):
    port = free_port()
    config = service_config(tmp_path, short_dir, service={"metrics_port": port})
    copy_state(cube_model_files, config)
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-3.0, 2.0, 0.0, -8.0)))
    with running_service(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                               FakeWrenchSensor())) as service, \
            client_for(service) as watcher, client_for(service) as client:
        events = watcher.events(timeout_s=EVENT_TIMEOUT_S)
        before = _scrape(port)
        assert before[("finepos_jobs_total", (("kind", "position"), ("outcome", "done")))] == 0
        assert before[("finepos_iteration_seconds_count", ())] == 0
        assert before[("finepos_state", (("finepos_state", "idle"),))] == 1

        job_id = client.call("position", max_loops=3)["job"]["id"]
        next(e for e in events if e["event"] == "iteration")
        during = _scrape(port)  # the listener counted the look before the stream carried it
        assert during[("finepos_iteration_seconds_count", ())] >= 1

        job = next(e for e in events if e["event"] == "job")["job"]
        assert job["id"] == job_id and job["outcome"] == "done", job
        after = _scrape(port)
        looks = job["result"]["iterations"] + 1  # every move's look, and the final check
        assert after[("finepos_jobs_total", (("kind", "position"), ("outcome", "done")))] == 1
        assert after[("finepos_iteration_seconds_count", ())] == looks
        assert after[("finepos_iteration_seconds_sum", ())] > 0
        assert after[("finepos_job_looks_count", ())] == 1
        assert after[("finepos_job_looks_sum", ())] == looks
        assert after[("finepos_control_clients", ())] == 2  # the watcher and the client
        assert 0 <= after[("finepos_seconds_since_last_done_job", ())] < EVENT_TIMEOUT_S
        model = [labels for name, labels in after if name == "finepos_model_info"]
        assert [dict(labels)["part"] for labels in model] == ["cube"]
        assert dict(model[0])["system"] == "gabor"

        answer = client.call("abort")  # idle: the arm is halted, no job preempted
        assert answer["halted"], answer
        aborted = _scrape(port)
        assert aborted[("finepos_aborts_total", (("halted", "true"),))] == 1
        assert aborted[("finepos_abort_seconds_count", ())] == 1
    with pytest.raises(urllib.error.URLError):  # the port closed with the service
        _scrape(port)


def test_a_non_loopback_bind_needs_the_tcp_token(tmp_path, short_dir):
    with pytest.raises(ConfigError, match="service: metrics_address: 0.0.0.0 is not loopback"):
        config_from_mapping({"service": {"metrics_port": 9400, "metrics_address": "0.0.0.0"}},
                            "<test>")
    with pytest.raises(ConfigError, match="metrics_address: expected an IP address"):
        config_from_mapping({"service": {"metrics_address": "localhost"}}, "<test>")

    port = free_port()
    config = service_config(tmp_path, short_dir, service={
        "metrics_port": port, "metrics_address": "0.0.0.0",
        "tcp": {"port": free_port(), "token_file": str(token_file(tmp_path))}})
    with running_service(config, device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())):
        for token in (None, "wrong-token-0123456789"):
            with pytest.raises(urllib.error.HTTPError) as refused:
                _scrape(port, token)
            assert refused.value.code == 401
        assert _scrape(port, TOKEN)[("finepos_control_clients", ())] == 0


def test_a_metrics_port_in_use_stops_the_start_with_one_line(tmp_path, short_dir):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        config = service_config(tmp_path, short_dir, service={"metrics_port": port})
        service = Service(config, opener=device_opener(FakeArm(), FakeCamera(),
                                                       FakeWrenchSensor()))
        with pytest.raises(ListenerError, match=f"service.metrics_port: cannot listen on "
                                                f"127.0.0.1:{port}: Address already in use"):
            service.run()
    assert not service.socket_path.exists()  # refused before the control socket was made


def test_grasps_and_faults_are_counted_from_their_events():
    metrics = ServiceMetrics(clients=lambda: 0, models=dict)
    grasp = {"success": False, "reason": "excessive force"}
    for event in (
        {"event": "job", "job": {"kind": "grasp", "outcome": "failed", "result": grasp}},
        {"event": "job", "job": {"kind": "position", "outcome": "done",
                                 "result": {"grasp": {**grasp, "success": True}}}},
        {"event": "job", "job": {"kind": "position", "outcome": "fault", "result": None}},
        {"event": "fault", "code": "device", "devices": {"arm": "fault", "camera": "inactive"}},
        {"event": "fault", "code": "device", "devices": {}},
        {"event": "fault", "code": "disk_full", "devices": {}},
    ):
        metrics.on_event(event)
    value = metrics.registry.get_sample_value
    assert value("finepos_grasps_total", {"result": "held"}) == 1
    assert value("finepos_grasps_total", {"result": "failed"}) == 1
    assert value("finepos_jobs_total", {"kind": "position", "outcome": "fault"}) == 1
    assert value("finepos_faults_total", {"device": "arm", "kind": "fault"}) == 1
    assert value("finepos_faults_total", {"device": "camera", "kind": "inactive"}) == 1
    assert value("finepos_faults_total", {"device": "none", "kind": "error"}) == 1
    assert value("finepos_faults_total", {"device": "none", "kind": "disk_full"}) == 1
