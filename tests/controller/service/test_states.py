"""The service's state machine and the reconnection backoff (pure)."""

from __future__ import annotations

import pytest

from controller.service.backoff import Backoff
from controller.service.states import JOB_STATES, TRANSITIONS, State, StateMachine, TransitionError


def test_every_state_has_its_transitions_and_stopping_is_final():
    assert set(TRANSITIONS) == set(State)
    assert TRANSITIONS[State.STOPPING] == frozenset()
    assert all(State.STOPPING in TRANSITIONS[s] for s in State if s is not State.STOPPING)


def test_jobs_start_only_from_idle_and_fault_is_left_only_to_idle():
    for job_state in JOB_STATES.values():
        assert [s for s in State if job_state in TRANSITIONS[s]] == [State.IDLE]
    assert TRANSITIONS[State.FAULT] == {State.IDLE, State.STOPPING}


def test_machine_refuses_a_forbidden_change_and_tells_listeners_of_the_others():
    heard = []
    machine = StateMachine(lambda old, new, reason: heard.append((old, new, reason)))
    machine.transition(State.IDLE, "devices open")
    machine.transition(State.POSITIONING, "job 1")
    with pytest.raises(TransitionError, match="positioning cannot change to acquiring"):
        machine.transition(State.ACQUIRING, "job 2")
    machine.transition(State.FAULT, "link lost")
    assert machine.snapshot()[0::2] == (State.FAULT, "link lost")
    assert [new for _, new, _ in heard] == [State.IDLE, State.POSITIONING, State.FAULT]


def test_backoff_doubles_up_to_the_cap():
    backoff = Backoff(0.5, 3.0)
    assert [backoff.next_delay_s() for _ in range(6)] == [0.5, 1.0, 2.0, 3.0, 3.0, 3.0]
    assert backoff.attempts == 6
    with pytest.raises(ValueError):
        Backoff(2.0, 1.0)
