"""The service's state machine: one state at a time, the transitions allowed between them.

starting -> idle once the devices are open (fault when they cannot be opened);
idle -> teaching | acquiring | training | rezeroing | positioning | grasping: one job at a time;
a job -> idle when it ends (done, failed or aborted), -> fault on a device error;
fault -> idle only through an accepted ``reset``; any state -> stopping on shutdown.
"""

from __future__ import annotations

import enum
import threading
import time
from collections.abc import Callable

from drivers.core.errors import FineposError


class State(enum.Enum):
    """The service's states; the value is the name ``status`` and state events report."""

    STARTING = "starting"
    IDLE = "idle"
    TEACHING = "teaching"
    ACQUIRING = "acquiring"
    TRAINING = "training"
    REZEROING = "rezeroing"
    POSITIONING = "positioning"
    GRASPING = "grasping"
    FAULT = "fault"
    STOPPING = "stopping"


JOB_STATES: dict[str, State] = {
    "teach": State.TEACHING,
    "acquire": State.ACQUIRING,
    "train": State.TRAINING,
    "rezero": State.REZEROING,
    "position": State.POSITIONING,
    "grasp": State.GRASPING,
}

_ENDS = frozenset({State.IDLE, State.FAULT, State.STOPPING})
TRANSITIONS: dict[State, frozenset[State]] = {
    State.STARTING: _ENDS,
    State.IDLE: frozenset({*JOB_STATES.values(), State.FAULT, State.STOPPING}),
    **{job: _ENDS for job in JOB_STATES.values()},
    State.FAULT: frozenset({State.IDLE, State.STOPPING}),
    State.STOPPING: frozenset(),
}


class TransitionError(FineposError):
    """A state change the machine does not allow (a bug in the caller)."""


Listener = Callable[[State, State, str], None]


class StateMachine:
    """The current state, since when, and why; listeners hear of every change.

    ``lock`` guards the state; hold it to test and change the state in one step. Listeners are
    called with the lock held, in the thread making the change, and must be quick.
    """

    def __init__(self, listener: Listener | None = None) -> None:
        self.lock = threading.RLock()
        self._state = State.STARTING
        self._since = time.time()
        self._reason = "starting"
        self._listener = listener

    @property
    def state(self) -> State:
        """The current state (read without the lock)."""
        return self._state

    def snapshot(self) -> tuple[State, float, str]:
        """(state, since as UNIX time, reason) read together."""
        with self.lock:
            return self._state, self._since, self._reason

    def transition(self, new: State, reason: str) -> None:
        """Change to ``new``; raises TransitionError when that change is not allowed."""
        with self.lock:
            old = self._state
            if new not in TRANSITIONS[old]:
                raise TransitionError(f"state {old.value} cannot change to {new.value}")
            self._state, self._since, self._reason = new, time.time(), reason
            if self._listener is not None:
                self._listener(old, new, reason)
