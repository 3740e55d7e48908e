"""How every server, emulator and helper process starts and stops: ``start()`` / ``close()``.

``Lifecycle`` is the verb pair: ``start()`` returns the started object, ``close()`` is idempotent,
and ``with obj:`` starts it and closes it on leaving the block. ``ThreadedServer`` is a lifecycle
serving from background threads until ``close()``, which tells them to end (``_closing`` is set,
then ``_interrupt`` cuts short whatever they wait on), joins them and releases what ``_open``
opened, so teardown is deterministic.
"""

from __future__ import annotations

import logging
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Self

logger = logging.getLogger(__name__)


class Lifecycle(ABC):
    """Started by ``start()``, stopped by ``close()``; a context manager doing both."""

    @abstractmethod
    def start(self) -> Self:
        """Start; returns self."""

    @abstractmethod
    def close(self) -> None:
        """Stop and release everything ``start`` took (idempotent)."""

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.close()


class ThreadedServer(Lifecycle):
    """Serves from the threads ``_open`` names until ``close()``; may be started again after."""

    def __init__(self) -> None:
        self._closing = threading.Event()  # set while close() ends the threads
        self._threads: list[threading.Thread] = []
        self._running = False

    def start(self) -> Self:
        """Open what is served (``_open``) and start its threads."""
        if self._running:
            raise RuntimeError(f"{type(self).__name__} is already started")
        self._closing.clear()
        bodies = self._open()
        self._threads = [threading.Thread(target=body, name=f"{type(self).__name__}-{name}",
                                          daemon=True)
                         for name, body in bodies.items()]
        self._running = True
        for thread in self._threads:
            thread.start()
        return self

    def close(self) -> None:
        """Stop serving: end and join every thread, then release (idempotent)."""
        if not self._running:
            return
        self._running = False
        self._closing.set()
        self._interrupt()
        for thread in self._threads:
            thread.join()
        self._threads = []
        self._release()
        logger.debug("%s closed", type(self).__name__)

    @abstractmethod
    def _open(self) -> dict[str, Callable[[], object]]:
        """Open what is served; returns the serving threads' bodies by name (at least one)."""

    @abstractmethod
    def _interrupt(self) -> None:
        """Make every thread body return soon: ``_closing`` is set, wake what they wait on."""

    @abstractmethod
    def _release(self) -> None:
        """Close what ``_open`` opened (the threads have ended)."""
