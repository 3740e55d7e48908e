"""3D mouse through the spacenavd daemon: socket client, typed events, jog mapping."""

from drivers.spacenav.client import SpacenavClient, resolve_socket_path
from drivers.spacenav.config import JogConfig
from drivers.spacenav.events import ButtonEvent, MotionEvent, SpnavEvent
from drivers.spacenav.jog import JogIntegrator, ToolRate, tool_rate

__all__ = ["ButtonEvent", "JogConfig", "JogIntegrator", "MotionEvent", "SpacenavClient",
           "SpnavEvent", "ToolRate", "resolve_socket_path", "tool_rate"]
