"""Signal handling for ``finepos serve``: SIGTERM and SIGINT stop the service, SIGHUP reloads.

The handlers only set the service's events (``Service.stop``, ``Service.request_reload``); the
control loop does the work. The previous handlers are restored on exit.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Callable, Iterator


@contextlib.contextmanager
def service_signals(stop: Callable[[], None], reload: Callable[[], None]) -> Iterator[None]:
    """Install the handlers (call from the main thread) for the duration of the block."""
    actions = {signal.SIGTERM: stop, signal.SIGINT: stop, signal.SIGHUP: reload}
    previous = {}
    try:
        for signum, action in actions.items():
            previous[signum] = signal.signal(signum, lambda _signum, _frame, act=action: act())
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
