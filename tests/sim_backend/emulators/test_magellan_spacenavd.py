"""End to end with the real spacenavd: Magellan emulator -> daemon -> our socket client.

Skipped with a reason where spacenavd is not installed; with FINEPOS_REQUIRE_SPACENAVD=1 (set
it in CI) a missing daemon fails instead.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from drivers.spacenav import ButtonEvent, JogConfig, JogIntegrator, MotionEvent, SpacenavClient
from sim_backend.emulators.magellan.emulator import MagellanEmulator
from sim_backend.emulators.magellan.script import Motion, click
from sim_backend.emulators.magellan.spacenavd import Spacenavd, find_spacenavd

TIMEOUT_S = 10.0

pytestmark = pytest.mark.slow


@pytest.fixture
def spacenavd_installed() -> None:
    if find_spacenavd() is None:
        message = "spacenavd is not installed (Debian: apt-get install -y spacenavd)"
        if os.environ.get("FINEPOS_REQUIRE_SPACENAVD") == "1":
            pytest.fail(message + " but FINEPOS_REQUIRE_SPACENAVD=1")
        pytest.skip(message)


@pytest.fixture
def daemon_and_mouse(spacenavd_installed, tmp_path):
    with MagellanEmulator() as mouse, Spacenavd(mouse.url, tmp_path) as daemon:
        assert mouse.wait_ready(TIMEOUT_S), daemon.log_tail()
        yield daemon, mouse


def events_until(client: SpacenavClient, done, limit: int = 500) -> list:
    events = []
    while not done(events) and len(events) < limit:
        event = client.next_event(TIMEOUT_S)
        assert event is not None, f"no event within {TIMEOUT_S} s after {events}"
        events.append(event)
    return events


def buttons_then_rest(events: list) -> bool:
    """All four button events came, then the cap's spring-back to rest."""
    last = events[-1] if events else None
    return (sum(isinstance(e, ButtonEvent) for e in events) == 4
            and isinstance(last, MotionEvent) and last.axes == (0,) * 6)


def test_probe_sequence_is_the_documented_one(daemon_and_mouse):
    _, mouse = daemon_and_mouse
    assert mouse.probe_log[:3] == ["@RESET", "vQ", "m3"]


def test_scripted_motion_and_buttons_arrive_with_the_right_axes(daemon_and_mouse):
    daemon, mouse = daemon_and_mouse
    with SpacenavClient(daemon.socket_path) as client:
        mouse.play([Motion((120, -45, 200, 0, 0, 0), 0.1),
                    Motion((0, 0, 0, 30, -40, 60), 0.1),
                    *click(0), *click(5)])
        events = events_until(client, buttons_then_rest)
    motions = [e.axes for e in events if isinstance(e, MotionEvent)]
    buttons = [e for e in events if isinstance(e, ButtonEvent)]
    # z and rz come out with the signs the script gave: the daemon undid the Magellan's negation
    assert motions[:2] == [(120, -45, 200, 0, 0, 0), (0, 0, 0, 30, -40, 60)]
    assert motions[-1] == (0, 0, 0, 0, 0, 0)
    assert buttons == [ButtonEvent(0, True), ButtonEvent(0, False),
                       ButtonEvent(5, True), ButtonEvent(5, False)]


def test_jog_from_real_events_moves_the_way_the_cap_was_pushed(daemon_and_mouse):
    daemon, mouse = daemon_and_mouse
    jog = JogIntegrator(JogConfig(max_period_ms=1000))
    with SpacenavClient(daemon.socket_path) as client:
        mouse.play([Motion((200, -200, -200, 0, -200, 0), 0.3)])
        events = events_until(client, lambda ev: len(ev) == 2)
    assert not jog.on_motion(events[0]).translation_mm  # nothing was held before
    step = jog.on_motion(events[1])  # the deflection, held for the event's period
    assert events[1].period_ms > 0 and not jog.moving
    assert step.dx_mm > 0 and step.dy_mm > 0 and step.dz_mm > 0 and step.dphi_deg > 0


def test_command_runs_the_daemon_and_plays_the_script_on_enter(spacenavd_installed, tmp_path):
    script = tmp_path / "jog.yaml"
    script.write_text("steps:\n  - {axes: [150, 0, -60, 0, 0, 0], duration_s: 0.1}\n"
                      "  - {button: 1, pressed: true}\n  - {button: 1, pressed: false}\n")
    command = ("import argparse, sys; from sim_backend.emulators.magellan import command as leaf; "
               "parser = argparse.ArgumentParser(); leaf.add_arguments(parser); "
               "sys.exit(leaf.run(parser.parse_args(sys.argv[1:])))")
    with subprocess.Popen([sys.executable, "-c", command, "--script", str(script),
                           "--spacenavd"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                          text=True) as process:
        assert process.stdout is not None and process.stdin is not None
        lines = [process.stdout.readline() for _ in range(3)]
        socket_path = lines[1].strip().removeprefix("SPNAV_SOCKET=")
        with SpacenavClient(socket_path) as client:
            process.stdin.write("\n")
            process.stdin.flush()
            events = events_until(client, lambda ev: len(ev) == 4)
        process.stdin.close()
        assert process.wait(TIMEOUT_S) == 0
    assert lines[0].startswith("Magellan mouse on /dev/pts/")
    assert events[0].axes == (150, 0, -60, 0, 0, 0)
    assert events[1:3] == [ButtonEvent(1, True), ButtonEvent(1, False)]
    assert events[3].axes == (0,) * 6
