"""Who is on the other end of the control socket, and whether they may use it.

``peer_credentials`` reads the connecting process's pid, uid and gid with SO_PEERCRED and its
supplementary groups with SO_PEERGROUPS (Linux >= 4.13; both are what the kernel recorded at
connect time, so they cannot be forged by the peer). ``PeerPolicy`` allows the service's own user,
the configured users, and members of the configured groups; names are resolved at start.
"""

from __future__ import annotations

import grp
import os
import pwd
import socket
import struct
from collections.abc import Iterable
from dataclasses import dataclass

from drivers.core.errors import ConfigError

# linux/asm-generic/socket.h; the socket module exports SO_PEERCRED but not this one.
SO_PEERGROUPS = 59
_MAX_PEER_GROUPS = 256  # getsockopt's buffer is at most 1024 bytes; more groups: refused
_CRED = struct.Struct("3i")  # struct ucred: pid, uid, gid


@dataclass(frozen=True)
class PeerCredentials:
    """A connected process's pid, uid, gid and supplementary groups (kernel-recorded)."""

    pid: int
    uid: int
    gid: int
    groups: tuple[int, ...]


def peer_credentials(sock: socket.socket) -> PeerCredentials:
    """The credentials of the process that connected ``sock`` (an AF_UNIX stream socket)."""
    pid, uid, gid = _CRED.unpack(sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                                 _CRED.size))
    raw = sock.getsockopt(socket.SOL_SOCKET, SO_PEERGROUPS, 4 * _MAX_PEER_GROUPS)
    groups = struct.unpack(f"{len(raw) // 4}I", raw[:len(raw) // 4 * 4])
    return PeerCredentials(pid, uid, gid, tuple(groups))


def resolve_uid(user: int | str) -> int:
    """The uid of a user given by number or name.

    Raises:
        ConfigError: (``service.allowed_users``) no user of that name on this system.
    """
    if isinstance(user, int):
        return user
    if user.isdigit():
        return int(user)
    try:
        return pwd.getpwnam(user).pw_uid
    except KeyError as exc:
        raise ConfigError(f"service.allowed_users: no user {user!r} on this system") from exc


def resolve_gid(group: int | str, key: str = "service.allowed_groups") -> int:
    """The gid of a group given by number or name; ``key`` is the config key errors name.

    Raises:
        ConfigError: no group of that name on this system.
    """
    if isinstance(group, int):
        return group
    if group.isdigit():
        return int(group)
    try:
        return grp.getgrnam(group).gr_gid
    except KeyError as exc:
        raise ConfigError(f"{key}: no group {group!r} on this system") from exc


@dataclass(frozen=True)
class PeerPolicy:
    """Allowed uids and gids (resolved); the service's own uid is always allowed."""

    uids: frozenset[int]
    gids: frozenset[int]

    @classmethod
    def from_config(cls, users: Iterable[int | str], groups: Iterable[int | str]) -> PeerPolicy:
        """The policy allowing the service's effective uid, ``users`` and members of ``groups``.

        Raises:
            ConfigError: a user or group name does not exist on this system.
        """
        return cls(frozenset({os.geteuid(), *(resolve_uid(u) for u in users)}),
                   frozenset(resolve_gid(g) for g in groups))

    def refusal(self, peer: PeerCredentials) -> str | None:
        """None when ``peer`` may connect, else why not (for the log and the response)."""
        if peer.uid in self.uids or self.gids.intersection((peer.gid, *peer.groups)):
            return None
        return f"uid {peer.uid} (pid {peer.pid}) is not an allowed user or group member"
