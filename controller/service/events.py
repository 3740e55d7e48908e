"""Fan-out of stream events (iteration records, state changes) to the streaming clients.

Publishing never blocks the publisher (the control loop writing its iteration log): each
subscriber has a bounded queue; when a slow client lets it fill up, further events are counted
and the client receives one ``{"event": "dropped", "count": N}`` before the next event it gets.
The iteration log file on disk has every record regardless.

Listeners (the metrics, ``controller.service.metrics``) are called with every event in the
publisher's thread, before any subscriber can read it; they only count, so they never block.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

logger = logging.getLogger(__name__)

QUEUE_EVENTS = 1000


class Subscription:
    """One client's queue; ``get`` returns the next event or None after ``timeout_s``."""

    def __init__(self, hub: EventHub, size: int) -> None:
        self._hub = hub
        self._queue: queue.Queue[dict[str, Any]] = queue.Queue(size)
        self._dropped = 0
        self._lock = threading.Lock()

    def put(self, event: dict[str, Any]) -> None:
        """Queue ``event`` without blocking; when the queue is full, drop and count it."""
        try:
            self._queue.put_nowait(event)
        except queue.Full:
            with self._lock:
                self._dropped += 1

    def get(self, timeout_s: float) -> dict[str, Any] | None:
        """The next event, or None when none arrives within ``timeout_s``.

        If events were dropped since the last call, it first returns ``{"event": "dropped",
        "count": N}``.
        """
        with self._lock:
            dropped, self._dropped = self._dropped, 0
        if dropped:
            return {"event": "dropped", "count": dropped}
        try:
            return self._queue.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def close(self) -> None:
        """Unsubscribe from the hub: no further events are queued."""
        self._hub.unsubscribe(self)


class EventHub:
    """Subscribers by identity; thread-safe."""

    def __init__(self, queue_events: int = QUEUE_EVENTS) -> None:
        self._queue_events = queue_events
        self._subscribers: list[Subscription] = []
        self._listeners: list[Callable[[dict[str, Any]], None]] = []
        self._lock = threading.Lock()

    def add_listener(self, listener: Callable[[dict[str, Any]], None]) -> None:
        """Call ``listener(event)`` with every event published from now on, in the publisher's
        thread and before subscribers see it; it must return quickly (an error it raises is
        logged, never passed to the publisher)."""
        with self._lock:
            self._listeners.append(listener)

    def subscribe(self) -> Subscription:
        """A new subscription that receives every event published from now on."""
        subscription = Subscription(self, self._queue_events)
        with self._lock:
            self._subscribers.append(subscription)
        return subscription

    def unsubscribe(self, subscription: Subscription) -> None:
        """Stop delivering to ``subscription`` (nothing happens if it is not subscribed)."""
        with self._lock:
            if subscription in self._subscribers:
                self._subscribers.remove(subscription)

    def publish(self, event: dict[str, Any]) -> None:
        """Hand ``event`` to every listener, then queue it for every subscriber; never blocks (a
        full queue drops it)."""
        with self._lock:
            listeners, subscribers = list(self._listeners), list(self._subscribers)
        for listener in listeners:
            try:
                listener(event)
            except Exception:  # a listener's bug must not end a job or the control loop
                logger.exception("event listener failed on a %s event", event.get("event"))
        for subscription in subscribers:
            subscription.put(event)
