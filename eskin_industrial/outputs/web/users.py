"""The console's users: the users file of :mod:`eskin_industrial.outputs.users` (its
format, its scrypt hashes and roles, the OPC UA server's too: one file may serve both
outputs; ``eskin-bus opcua user add FILE NAME --role reader|operator`` writes it).
A reader sees every page; an operator also commands.

A login costs one scrypt (0.05 to 0.15 s) on the server's executor, never on a node's
loop; an unknown name costs the same as a wrong password.
"""

from __future__ import annotations

from ..users import ROLES, Role, UserEntry, check_login, read_users_file

__all__ = ["ROLES", "Role", "WebUser", "load_users", "login"]

WebUser = UserEntry


def load_users(path: str) -> tuple[WebUser, ...]:
    """The users of the file; ValueError ``users_file: PATH: [[user]] N: key: what``."""
    return read_users_file(path)


def login(users: dict[str, WebUser], name: str, password: str) -> Role | None:
    """The user's role when the password is right, else None (the same work either way)."""
    return check_login(users, name, password)
