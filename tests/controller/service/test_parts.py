"""The service with several parts taught: a model slot per part, loaded once; jobs take
``part``; ``status`` lists the taught parts; a state folder of one part at its top still
serves."""

from __future__ import annotations

import pytest

from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.service.client import ServiceError
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    NOMINAL,
    client_for,
    copy_state,
    cube_view,
    device_opener,
    running_service,
    service_config,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor


@pytest.fixture
def positioned(monkeypatch) -> list[tuple[str, object]]:
    """Every positioning run's (part, model object in use), in order."""
    runs: list[tuple[str, object]] = []
    original = FinePositioner.position

    def position(self, max_loops=None, then_grasp=False):
        runs.append((self.config.controller.part, self._model))
        return original(self, max_loops, then_grasp)

    monkeypatch.setattr(FinePositioner, "position", position)
    return runs


def _fake_cell():
    arm = FakeArm(start=NOMINAL)
    return device_opener(arm, FakeCamera(cube_view(arm)), FakeWrenchSensor())


def test_two_taught_parts_position_one_then_the_other_without_reloading(
        tmp_path, short_dir, two_part_model_files, positioned):
    config = service_config(tmp_path, short_dir)
    state = copy_state(two_part_model_files, config)
    with running_service(config, _fake_cell()) as service, client_for(service) as client:
        status = client.call("status")
        assert sorted(status["parts"]) == ["cube", "nut"]
        loaded = {kind: entry["model"] for kind, entry in status["parts"].items()}
        assert loaded["cube"]["file"] == str(state / "cube" / "model-gabor.fpm")
        assert loaded["nut"]["file"] == str(state / "nut" / "model-gabor.fpm")
        models = {kind: service._models.slot(kind).model for kind in ("cube", "nut")}
        with pytest.raises(ServiceError) as ambiguous:  # two taught, none named
            client.call("position", wait=True)
        assert ambiguous.value.code == "bad_request"
        assert "several parts are taught (cube, nut)" in ambiguous.value.message
        for kind in ("cube", "nut", "cube"):
            job = client.call("position", wait=True, part=kind, max_loops=1,
                              timeout_s=EVENT_TIMEOUT_S)["job"]
            assert job["args"]["part"] == kind and job["result"]["part"] == kind, job
            assert job["outcome"] != "fault", job
            status = client.call("status")
            assert status["part"] == kind and status["model"] == loaded[kind]
        assert [(kind, model) for kind, model in positioned] == \
            [("cube", models["cube"]), ("nut", models["nut"]), ("cube", models["cube"])]
        after = {kind: entry["model"] for kind, entry in client.call("status")["parts"].items()}
        assert after == loaded  # same files, same load times: nothing was reloaded
        reloaded = client.call("reload", part="nut")
        assert set(reloaded["models"]) == {"nut"}
        assert reloaded["models"]["nut"]["loaded_at"] > loaded["nut"]["loaded_at"]
        assert client.call("status")["parts"]["cube"]["model"] == loaded["cube"]


def test_a_job_for_a_part_not_taught_fails_and_names_it(tmp_path, short_dir,
                                                       two_part_model_files):
    config = service_config(tmp_path, short_dir)
    copy_state(two_part_model_files, config)
    with running_service(config, _fake_cell()) as service, client_for(service) as client:
        job = client.call("position", wait=True, part="screw")["job"]
        assert job["outcome"] == "failed" and "screw" in job["reason"], job
        assert "no cell state yet" in job["reason"]
        with pytest.raises(ServiceError, match=r"unknown part 'bolt' \(known parts: cube, nut, "
                                               r"ledge, screw; declare"):
            client.call("position", part="bolt")
        assert client.call("status")["state"] == "idle"


def test_teach_with_part_writes_that_parts_folder(tmp_path, short_dir, cube_model_files):
    config = service_config(tmp_path, short_dir, controller={"part": "ledge"})
    state = copy_state(cube_model_files, config)  # a single-part folder: the cube at its top
    with running_service(config, _fake_cell()) as service, client_for(service) as client:
        status = client.call("status")
        assert list(status["parts"]) == ["cube"]
        assert status["parts"]["cube"]["state_dir"] == str(state)
        assert status["parts"]["cube"]["model"]["file"] == str(state / "model-gabor.fpm")
        job = client.call("position", wait=True, max_loops=1)["job"]  # the one taught
        assert job["args"]["part"] == "cube" and job["outcome"] != "fault", job
        job = client.call("teach", wait=True, part="ledge")["job"]
        assert job["outcome"] == "done", job
        assert job["result"]["state_file"] == str(state / "ledge" / "cell.json")
        assert job["result"]["kappa"] == 2
        assert sorted(client.call("status")["parts"]) == ["cube", "ledge"]


@pytest.mark.slow
def test_simulated_service_taught_two_parts_positions_either(tmp_path, short_dir, positioned):
    """On the simulated cell a job's part is put on the table: teach, acquire and train the
    cube and the nut in one service, then position each without loading a model again."""
    config = service_config(tmp_path, short_dir, controller={
        "acquisition": {"nn1": {"shape": [3, 3, 3]}, "nn2": {"shape": [3, 3, 3]}}})
    with running_service(config, open_devices) as service, client_for(service) as client:
        for kind in ("cube", "nut"):
            for cmd, args in (("teach", {"auto": True}), ("acquire", {"set": "nn1"}),
                              ("acquire", {"set": "nn2"}), ("train", {})):
                job = client.call(cmd, wait=True, part=kind, timeout_s=None, **args)["job"]
                assert job["outcome"] == "done" and job["result"]["part"] == kind, job
        assert service._cell.cell.object_kind == "nut"
        loaded = {kind: entry["model"] for kind, entry in client.call("status")["parts"].items()}
        assert sorted(loaded) == ["cube", "nut"] and all(loaded.values())
        for kind in ("cube", "nut"):
            job = client.call("position", wait=True, part=kind, offset=[3.0, -2.0, 4.0],
                              max_loops=2, timeout_s=None)["job"]
            assert job["outcome"] != "fault" and job["result"]["part"] == kind, job
            assert service._cell.cell.object_kind == kind
        after = {kind: entry["model"] for kind, entry in client.call("status")["parts"].items()}
        assert after == loaded
        assert [kind for kind, _ in positioned] == ["cube", "nut"]


def test_a_rezero_job_rewrites_the_parts_model_and_puts_it_in_use(tmp_path, short_dir,
                                                                  cube_model_files):
    config = service_config(tmp_path, short_dir)
    state = copy_state(cube_model_files, config)
    with running_service(config, _fake_cell()) as service, client_for(service) as client:
        before = service._models.slot("cube").model
        job = client.call("rezero", wait=True, part="cube", frames=3)["job"]
        assert job["outcome"] == "done", job
        result = job["result"]
        assert result["model"] == str(state / "model-gabor.fpm") and result["frames"] == 3
        assert set(result["shift_mm"]) >= {"nn1", "nn1_rot"}
        now = service._models.slot("cube").model
        assert now is not before and now.model.training["rezero"][-1]["frames"] == 3
        assert result["system"] == "gabor"
        with pytest.raises(ServiceError, match="frames: must be within"):
            client.call("rezero", frames=0)
        with pytest.raises(ServiceError, match="system: one of gabor, align, got .pca."):
            client.call("rezero", system="pca")
        job = client.call("rezero", wait=True, part="cube", system="align")["job"]
        assert job["outcome"] == "failed" and "no trained align model" in job["reason"], job
        assert service._models.slot("cube").model is now  # the Gabor model stays in use
        # by heading: the fake gripper closes on nothing, so the first grasp (for the cube: to
        # centre it at the taught heading) fails the job, and the model in use and its file
        # stay as they were
        written = (state / "model-gabor.fpm").read_bytes()
        job = client.call("rezero", wait=True, part="cube", frames=3, heading_step=45.0)["job"]
        assert job["outcome"] == "failed", job
        assert "the grasp to centre the part at 0 deg failed" in job["reason"], job
        assert service._models.slot("cube").model is now
        assert (state / "model-gabor.fpm").read_bytes() == written
        with pytest.raises(ServiceError, match="heading_step: must be within"):
            client.call("rezero", heading_step=0.1)
        assert client.call("status")["state"] == "idle"


def test_a_position_job_with_grasp_grasps_where_the_loop_ended(tmp_path, short_dir,
                                                              two_part_model_files):
    config = service_config(tmp_path, short_dir)
    copy_state(two_part_model_files, config)
    with running_service(config, _fake_cell()) as service, client_for(service) as client:
        job = client.call("position", wait=True, part="cube", max_loops=1, grasp=True,
                          timeout_s=EVENT_TIMEOUT_S)["job"]
        # the loop ended within its budget, the grasp followed in the same job; the fake
        # gripper closes on nothing, so the grip check fails and the grasp retreats
        assert job["outcome"] == "failed", job
        assert job["reason"].startswith("grasp failed: grip check failed"), job
        assert job["result"]["outcome"] in ("converged", "budget")
        assert job["result"]["grasp"]["retreated"] is True
        assert client.call("status")["state"] == "idle"
