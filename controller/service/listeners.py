"""The service's listening sockets: the UNIX control socket (mode 0660, chosen group) and the
optional loopback TCP port, plus the TCP token.

``bind_unix`` refuses to replace anything but a stale socket (one nobody answers on), creates
the socket with a umask that leaves no moment at a wider mode, and sets its group. The caller
removes it on shutdown with ``unlink_if_ours`` (only if the path is still the socket it made).
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import stat
from pathlib import Path

from controller.service.config import TcpConfig
from drivers.core.errors import ConfigError, FineposError
from drivers.core.files import FileReadError, read_regular_file

logger = logging.getLogger(__name__)

SOCKET_MODE = 0o660
BACKLOG = 64
MIN_TOKEN_CHARS = 16
MAX_TOKEN_FILE_BYTES = 4096  # a token is one short line
_PROBE_TIMEOUT_S = 1.0


class ListenerError(FineposError):
    """The control socket cannot be created (path taken, or another service answers on it)."""


def _remove_stale(path: Path) -> None:
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    if not stat.S_ISSOCK(info.st_mode):
        raise ListenerError(f"{path} exists and is not a socket; not replacing it")
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.settimeout(_PROBE_TIMEOUT_S)
        try:
            probe.connect(str(path))
        except (ConnectionRefusedError, FileNotFoundError):
            os.unlink(path)
            logger.info("removed the stale control socket %s", path)
            return
        except OSError as exc:
            raise ListenerError(f"cannot tell whether {path} is in use: {exc}") from exc
    raise ListenerError(f"another service is listening on {path}")


def bind_unix(path: Path, group_id: int | None) -> tuple[socket.socket, int]:
    """A listening AF_UNIX socket at ``path``, mode 0660, group ``group_id`` (None: ours).

    Returns the socket and the inode of its file (for ``unlink_if_ours``).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale(path)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
    try:
        previous = os.umask(0o777 & ~SOCKET_MODE)
        try:
            sock.bind(str(path))
        finally:
            os.umask(previous)
        os.chmod(path, SOCKET_MODE)
        if group_id is not None:
            os.chown(path, -1, group_id)
        sock.listen(BACKLOG)
    except BaseException:
        sock.close()
        raise
    return sock, os.lstat(path).st_ino


def unlink_if_ours(path: Path, inode: int) -> None:
    """Remove the socket file unless something else has replaced it meanwhile."""
    with contextlib.suppress(FileNotFoundError):
        if os.lstat(path).st_ino == inode:
            os.unlink(path)


def bind_tcp(config: TcpConfig) -> socket.socket:
    """The loopback TCP listener (the host was checked to be loopback at config load)."""
    family = socket.AF_INET6 if ":" in config.host else socket.AF_INET
    return socket.create_server((config.host, config.port), family=family, backlog=BACKLOG)


def read_token(token_file: str | Path) -> str:
    """The TCP token: the first line of ``token_file``, which only its owner may read.

    Raises:
        ConfigError: the file cannot be read, is not a regular file (a FIFO or a device is
            never opened for a blocking or endless read), is over MAX_TOKEN_FILE_BYTES, is
            not UTF-8, is open to group or others, or its token is too short.
    """
    path = Path(token_file)
    try:
        info = path.stat()
        raw = read_regular_file(path, MAX_TOKEN_FILE_BYTES)  # a FIFO or device: an error
        text = raw.decode("utf-8")
    except FileReadError as exc:
        raise ConfigError(f"service.tcp.token_file: {path}: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"service.tcp.token_file: cannot read {path}: "
                          f"{exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"service.tcp.token_file: {path} is not UTF-8 text") from exc
    if info.st_mode & 0o077:
        raise ConfigError(f"service.tcp.token_file: {path} must not be accessible to group or "
                          f"others (mode {stat.S_IMODE(info.st_mode):o}; chmod 600 it)")
    token = text.splitlines()[0].strip() if text.strip() else ""
    if len(token) < MIN_TOKEN_CHARS:
        raise ConfigError(f"service.tcp.token_file: the token in {path} must have at least "
                          f"{MIN_TOKEN_CHARS} characters")
    return token
