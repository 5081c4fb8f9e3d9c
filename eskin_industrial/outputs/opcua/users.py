"""Username/password users of the OPC UA server and their roles, from the users file
(:mod:`eskin_industrial.outputs.users`: its format, hashes and roles, shared with the
web console) or from an environment variable (never from the command line: ``ps``
and the shell's history would show a password).

The environment variable holds one user a line, ``NAME:ROLE:PASSWORD`` (the password
in clear or as the file's hash), for a container or a systemd ``Environment=``.

A login costs one scrypt (0.05 to 0.15 s): a guessing client is slowed, the bridge's
loop is not (the server has its own thread).  A successful login is remembered (a
SHA-256 of the password in memory) so that a client that reconnects pays it once.
"""

from __future__ import annotations

import hashlib
import hmac
import os

from ..users import (
    DUMMY,
    ROLES,
    Role,
    UserEntry,
    add_user,
    entry,
    hash_password,
    parse_users_file,
    read_users_file,
    unique,
    verify_password,
)

__all__ = ["ROLES", "Directory", "Role", "UserEntry", "add_user", "hash_password", "load_users", "parse_users_env",
           "parse_users_file", "verify_password"]


def parse_users_env(text: str, name: str) -> tuple[UserEntry, ...]:
    """``NAME:ROLE:PASSWORD`` lines of the environment variable ``name``."""
    out = []
    for i, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        user, sep, rest = line.partition(":")
        role, sep2, password = rest.partition(":")
        if not sep or not sep2:
            raise ValueError(f"users_env: ${name} line {i}: expected NAME:ROLE:PASSWORD")
        out.append(entry(user, role, password, f"users_env: ${name} line {i}"))
    return unique(out, f"users_env: ${name}")


def load_users(users_file: str | None, users_env: str | None) -> tuple[UserEntry, ...]:
    """The configured users (none when neither is set); ValueError ``key: what``."""
    if users_file is not None:
        return read_users_file(users_file)
    if users_env is not None:
        value = os.environ.get(users_env)
        if value is None:
            raise ValueError(f"users_env: the environment variable {users_env} is not set")
        return parse_users_env(value, users_env)
    return ()


class Directory:
    """The users, checked at each login (the server's thread)."""

    def __init__(self, users: tuple[UserEntry, ...]) -> None:
        self.users = {u.name: u for u in users}
        self._remembered: dict[str, bytes] = {}  #: name -> SHA-256 of the password that logged in

    def login(self, name: str, password: str) -> Role | None:
        """The user's role when the password is right, else None."""
        user = self.users.get(name)
        if user is None:
            # the same work as a wrong password: a name is not told apart by the time taken
            verify_password(DUMMY, password)
            return None
        quick = hashlib.sha256(password.encode("utf-8")).digest()
        known = self._remembered.get(name)
        if known is not None and hmac.compare_digest(known, quick):
            return user.role
        if not verify_password(user.password, password):
            return None
        self._remembered[name] = quick
        return user.role
