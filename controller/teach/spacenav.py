"""Teach-in with a 3D mouse through spacenavd: jog the arm in the tool frame, a button records.

``finepos teach --device spacenav`` connects to spacenavd's socket
(``controller.teach.socket_path``, else ``$SPNAV_SOCKET``, else ``/var/run/spnav.sock``) and
turns motion events into tool-frame jog steps (``drivers.spacenav.JogIntegrator``: deadband,
scaling and axis mapping from ``controller.teach.jog``). The jog accumulated over
``move_period_s`` goes to the arm as one ``arm.move_tool`` step, so every step passes the arm's
safety layer; a refused step is logged and the jog stops until the cap moves again. Speed is
bounded by the jog's maximum speeds: the integrator never yields more than the maximum speed
times the time that passed.

Pressing ``record_button`` applies what is still pending and records the arm's pose as the
nominal pre-grasp pose (``FinePositioner.teach("spacenav")``, an atomic write of the state
file). Pressing ``abort_button`` (or the optional timeout) raises ``TeachAborted`` and writes
nothing. On the simulated cell the arm first goes to the part's grasp pose displaced by a start
offset, so there is something to jog.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

from drivers.core.cell_state import CellState
from drivers.core.errors import FineposError, MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.spacenav import ButtonEvent, JogConfig, JogIntegrator, MotionEvent, SpacenavClient

logger = logging.getLogger(__name__)

# (dx_mm, dy_mm, dphi_deg): the simulated arm starts at the grasp pose displaced by
# -(dx, dy, dphi) in the tool frame (the convention of ``finepos position --offset``).
DEFAULT_SIM_START_OFFSET = (4.0, -3.0, 5.0)
_IDLE_WAIT_S = 0.5  # longest wait for an event while nothing moves (the timeout is checked)


@dataclass(frozen=True)
class TeachConfig:
    """Config section ``controller.teach``: teach-in with a 3D mouse.

    socket_path: spacenavd's socket (None: ``$SPNAV_SOCKET``, else ``/var/run/spnav.sock``);
    record_button / abort_button: button numbers (from 0) that record the pose / abort without
    writing anything;
    move_period_s: the jog accumulated over this long is sent to the arm as one step (a slow
    link, e.g. VAL at 9600 baud, simply gets fewer, larger steps);
    jog: deflection to tool-frame speed (``drivers.spacenav.JogConfig``).
    """

    socket_path: str | None = None
    record_button: int = field(default=0, metadata={"min": 0})
    abort_button: int = field(default=1, metadata={"min": 0})
    move_period_s: float = field(default=0.05, metadata={"min": 0.0, "exclusive_min": True})
    jog: JogConfig = JogConfig()

    def __post_init__(self) -> None:
        if self.record_button == self.abort_button:
            raise ValueError(f"record_button and abort_button must differ, both are "
                             f"{self.record_button}")


class TeachAborted(FineposError):
    """Teach-in ended without recording (abort button or timeout); nothing was written."""


def displaced(nominal: Pose, offset: tuple[float, float, float]) -> Pose:
    """``nominal`` displaced by -(dx_mm, dy_mm, dphi_deg) in its tool frame."""
    dx_mm, dy_mm, dphi_deg = offset
    return nominal.moved_in_tool_frame(ToolStep(-dx_mm, -dy_mm, 0.0, -dphi_deg))


def teach_with_spacenav(fp, *, start_offset: tuple[float, float, float] | None = None,
                        socket_path: str | None = None, grasp_depth_mm: float | None = None,
                        object_width_mm: float | None = None,
                        timeout_s: float | None = None) -> CellState:
    """Jog with the 3D mouse until the record button; returns the recorded state.

    Args:
        fp: the FinePositioner (its devices, config and state file).
        start_offset: simulated cell only: start at the grasp pose displaced by this
            (mm, mm, deg; default ``DEFAULT_SIM_START_OFFSET``).
        socket_path: overrides ``controller.teach.socket_path``.
        grasp_depth_mm / object_width_mm: the part's grasp geometry (a real cell needs both).
        timeout_s: give up (TeachAborted, nothing written) after this long; None: wait.
    """
    cfg = fp.config.controller.teach
    cell = fp.devices.cell
    if cell is not None:
        offset = start_offset or DEFAULT_SIM_START_OFFSET
        fp.move_to(displaced(cell.nominal_grasp_pose(), offset))
        logger.info("teach-in: simulated arm placed at (%g mm, %g mm, %g deg) from the grasp "
                    "pose", *offset)
    elif start_offset is not None:
        raise FineposError("--start-offset places the simulated arm; on a real cell jog from "
                           "where the arm is")
    with SpacenavClient(socket_path or cfg.socket_path) as client:
        return jog_and_record(fp, client, cfg, grasp_depth_mm=grasp_depth_mm,
                              object_width_mm=object_width_mm, timeout_s=timeout_s)


def jog_and_record(fp, client: SpacenavClient, cfg: TeachConfig, *,
                   grasp_depth_mm: float | None = None, object_width_mm: float | None = None,
                   timeout_s: float | None = None) -> CellState:
    """The teach-in loop on a connected client (see the module docstring)."""
    jog = _Jog(fp.devices.arm, cfg)
    deadline_s = None if timeout_s is None else time.monotonic() + timeout_s
    logger.info("teach-in: jog with the 3D mouse; button %d records the pose, button %d aborts",
                cfg.record_button, cfg.abort_button)
    while True:
        now_s = time.monotonic()
        if deadline_s is not None and now_s >= deadline_s:
            raise TeachAborted(f"teach-in: no record button within {timeout_s:g} s; nothing "
                               "written")
        wait_s = jog.next_move_s - now_s if jog.active else _IDLE_WAIT_S
        if deadline_s is not None:
            wait_s = min(wait_s, deadline_s - now_s)
        event = client.next_event(max(0.0, wait_s))
        if isinstance(event, MotionEvent):
            jog.on_motion(event)
        elif isinstance(event, ButtonEvent) and event.pressed:
            if event.button == cfg.abort_button:
                raise TeachAborted("teach-in aborted by the operator; nothing written")
            if event.button == cfg.record_button:
                jog.finish()
                logger.info("teach-in: recording after %d jog moves (%d refused)", jog.moves,
                            jog.refused)
                return fp.teach("spacenav", grasp_depth_mm, object_width_mm)
            logger.debug("teach-in: button %d has no function", event.button)
        jog.tick()


class _Jog:
    """Jog steps accumulated from events (and from a held deflection), sent once per period."""

    def __init__(self, arm, cfg: TeachConfig) -> None:
        self.arm = arm
        self.period_s = cfg.move_period_s
        self.integrator = JogIntegrator(cfg.jog)
        self.pending = ToolStep()
        self.moves = 0
        self.refused = 0
        self._integrated_s = time.monotonic()  # the held deflection is applied up to here
        self.next_move_s = self._integrated_s + self.period_s

    @property
    def active(self) -> bool:
        """A deflection is held or a step waits to be sent."""
        return self.integrator.moving or self.pending != ToolStep()

    def on_motion(self, event: MotionEvent) -> None:
        """Add the previous deflection over the event's period; take on the new one."""
        self._add(self.integrator.on_motion(event))
        self._integrated_s = time.monotonic()

    def tick(self) -> None:
        """Apply the held deflection up to now; send the pending step when a period is up."""
        now_s = time.monotonic()
        if self.integrator.moving:
            self._add(self.integrator.hold(now_s - self._integrated_s))
        self._integrated_s = now_s
        if now_s >= self.next_move_s:
            self._send()
            self.next_move_s = time.monotonic() + self.period_s

    def finish(self) -> None:
        """Apply the held deflection up to now and send what is pending, then stop."""
        if self.integrator.moving:
            self._add(self.integrator.hold(time.monotonic() - self._integrated_s))
        self._send()
        self.integrator.stop()

    def _add(self, step: ToolStep) -> None:
        p = self.pending
        self.pending = ToolStep(p.dx_mm + step.dx_mm, p.dy_mm + step.dy_mm,
                                p.dz_mm + step.dz_mm, p.dphi_deg + step.dphi_deg)

    def _send(self) -> None:
        step, self.pending = self.pending, ToolStep()
        if step == ToolStep():
            return
        try:
            self.arm.move_tool(step)
            self.moves += 1
        except MotionRejectedError as exc:
            self.refused += 1
            logger.warning("teach-in: jog step %s refused (%s); move the cap again",
                           step.as_dict(), exc.reason)
            self.integrator.stop()
