"""The console's users: the OPC UA output's users file, read as it reads it
(``eskin-bus opcua user add FILE NAME --role reader|operator`` writes it; one file may
serve both outputs), checked here again because each output kind stands on its own::

    [[user]]
    name = "operator1"
    role = "operator"        # reader: every page; operator: also the commands
    password = "scrypt$16384$8$1$<salt>$<hash>"

Only hashed passwords are accepted (hashlib.scrypt, salted).  A login costs one scrypt
(0.05 to 0.15 s) on the server's executor, never on a node's loop; an unknown name
costs the same as a wrong password.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

Role = Literal["reader", "operator"]
ROLES: tuple[Role, ...] = ("reader", "operator")
_MAXMEM = 64 * 1024 * 1024


@dataclass(frozen=True)
class WebUser:
    name: str
    role: Role
    password: str  #: ``scrypt$N$R$P$SALT$HASH`` (base64)


def verify_password(stored: str, password: str) -> bool:
    """``password`` against a stored scrypt hash."""
    try:
        kind, n, r, p, salt, digest = stored.split("$")
        if kind != "scrypt":
            return False
        want = base64.b64decode(digest)
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt), n=int(n), r=int(r), p=int(p),
                             maxmem=_MAXMEM, dklen=len(want))
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)


def _hash_ok(stored: object) -> bool:
    if not isinstance(stored, str):
        return False
    parts = stored.split("$")
    try:
        return (len(parts) == 6 and parts[0] == "scrypt" and all(int(x) > 0 for x in parts[1:4])
                and bool(base64.b64decode(parts[4], validate=True)) and bool(base64.b64decode(parts[5], validate=True)))
    except ValueError:
        return False


def load_users(path: str) -> tuple[WebUser, ...]:
    """The users of the file; ValueError ``users_file: PATH: [[user]] N: key: what``."""
    where = f"users_file: {path}"
    try:
        table = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ValueError(f"{where}: cannot read: {reason}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{where}: not valid TOML: {exc}") from None
    raw = table.get("user", [])
    if set(table) - {"user"} or not isinstance(raw, list):
        raise ValueError(f"{where}: expected [[user]] tables only")
    users: dict[str, WebUser] = {}
    for i, u in enumerate(raw):
        at = f"{where}: [[user]] {i}"
        if not isinstance(u, dict):
            raise ValueError(f"{at}: expected a table")
        name, role, password = u.get("name"), u.get("role"), u.get("password")
        if not isinstance(name, str) or not name or ":" in name or name != name.strip():
            raise ValueError(f"{at}: name: expected a user name without ':' or spaces around it, got {name!r}")
        if role not in ROLES:
            raise ValueError(f"{at}: role: expected one of {', '.join(ROLES)}, got {role!r}")
        if not _hash_ok(password):
            raise ValueError(f"{at}: password: expected a hash written by 'eskin-bus opcua user add' (scrypt$...)")
        if name in users:
            raise ValueError(f"{where}: user {name!r} is given twice")
        users[name] = WebUser(name, role, str(password))
    return tuple(users.values())


_DUMMY = "scrypt$16384$8$1$AAAAAAAAAAAAAAAAAAAAAA==$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA="


def login(users: dict[str, WebUser], name: str, password: str) -> Role | None:
    """The user's role when the password is right, else None (the same work either way)."""
    user = users.get(name)
    if user is None:
        verify_password(_DUMMY, password)
        return None
    return user.role if verify_password(user.password, password) else None
