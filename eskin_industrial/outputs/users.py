"""The users file of the outputs that log users in (the OPC UA server, the web
console): its format, its scrypt hashes and the roles, one module for both, so that
one file may serve both outputs.  ``eskin-bus opcua user add FILE NAME --role ROLE``
writes it (it asks for the password), one table per user::

    [[user]]
    name = "operator1"
    role = "operator"        # reader: read and watch; operator: also the commands
    password = "scrypt$16384$8$1$<salt>$<hash>"

A file holds salted scrypt hashes only (hashlib.scrypt).  A login costs one scrypt (0.05
to 0.15 s), on the server's own thread or executor, never on a node's loop; an unknown
name costs the same as a wrong password.  What each output does beside (the OPC UA
server's users from an environment variable and its remembered logins) is its own.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import secrets
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

Role = Literal["reader", "operator"]
ROLES: tuple[Role, ...] = ("reader", "operator")
_SCRYPT = (16384, 8, 1)  #: n, r, p: 16 MB and 0.05 to 0.15 s a hash
_MAXMEM = 64 * 1024 * 1024
#: The hash an unknown name is checked against: the same work as a wrong password.
DUMMY = "scrypt$16384$8$1$AAAAAAAAAAAAAAAAAAAAAA==$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA="


@dataclass(frozen=True)
class UserEntry:
    name: str
    role: Role
    #: ``scrypt$N$R$P$SALT$HASH`` (base64), or the password itself (the OPC UA
    #: output's environment variable; never from a file).
    password: str


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """A salted scrypt hash of ``password`` in the file's form."""
    n, r, p = _SCRYPT
    salt = salt or secrets.token_bytes(16)
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=n, r=r, p=p, maxmem=_MAXMEM, dklen=32)
    return f"scrypt${n}${r}${p}${_b64(salt)}${_b64(digest)}"


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def verify_password(stored: str, password: str) -> bool:
    """``password`` against a stored hash (or a clear password from an environment)."""
    if not stored.startswith("scrypt$"):
        return hmac.compare_digest(stored.encode("utf-8"), password.encode("utf-8"))
    try:
        _, n, r, p, salt, digest = stored.split("$")
        want = base64.b64decode(digest)
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt), n=int(n), r=int(r), p=int(p),
                             maxmem=_MAXMEM, dklen=len(want))
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)


def check_login(users: dict[str, UserEntry], name: str, password: str) -> Role | None:
    """The user's role when the password is right, else None (the same work either way:
    a name is not told apart by the time taken)."""
    user = users.get(name)
    if user is None:
        verify_password(DUMMY, password)
        return None
    return user.role if verify_password(user.password, password) else None


def _check_hash(stored: str, where: str) -> None:
    parts = stored.split("$")
    try:
        ok = len(parts) == 6 and parts[0] == "scrypt" and all(int(x) > 0 for x in parts[1:4])
        base64.b64decode(parts[4], validate=True)
        base64.b64decode(parts[5], validate=True)
    except (ValueError, IndexError):
        ok = False
    if not ok:
        raise ValueError(f"{where}: password: expected a hash written by 'eskin-bus opcua user add' (scrypt$...)")


def entry(name: object, role: object, password: object, where: str) -> UserEntry:
    """One user, checked; ValueError ``WHERE: key: what``."""
    if not isinstance(name, str) or not name or ":" in name or name != name.strip():
        raise ValueError(f"{where}: name: expected a user name without ':' or spaces around it, got {name!r}")
    if role not in ROLES:
        raise ValueError(f"{where}: role: expected one of {', '.join(ROLES)}, got {role!r}")
    if not isinstance(password, str) or not password:
        raise ValueError(f"{where}: password: missing")
    return UserEntry(name, role, password)


def parse_users_file(text: str, source: str) -> tuple[UserEntry, ...]:
    """The users of a file's text; ValueError ``SOURCE: [[user]] N: key: what``."""
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {exc}") from None
    unknown = set(table) - {"user"}
    if unknown:
        raise ValueError(f"{source}: [{sorted(unknown)[0]}]: unknown section; expected [[user]] tables")
    raw = table.get("user", [])
    if not isinstance(raw, list):
        raise ValueError(f"{source}: user: expected [[user]] tables")
    out: list[UserEntry] = []
    for i, u in enumerate(raw):
        where = f"{source}: [[user]] {i}"
        if not isinstance(u, dict):
            raise ValueError(f"{where}: expected a table")
        extra = set(u) - {"name", "role", "password"}
        if extra:
            raise ValueError(f"{where}: {sorted(extra)[0]}: unknown key; valid keys: name, role, password")
        user = entry(u.get("name"), u.get("role"), u.get("password"), where)
        _check_hash(user.password, where)
        out.append(user)
    return unique(out, source)


def read_users_file(path: str) -> tuple[UserEntry, ...]:
    """The users of the file at ``path``; ValueError ``users_file: PATH: what``."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ValueError(f"users_file: {path}: cannot read: {reason}") from None
    return parse_users_file(text, f"users_file: {path}")


def unique(users: list[UserEntry], source: str) -> tuple[UserEntry, ...]:
    """``users``, refused when a name is given twice."""
    seen: set[str] = set()
    for u in users:
        if u.name in seen:
            raise ValueError(f"{source}: user {u.name!r} is given twice")
        seen.add(u.name)
    return tuple(users)


def add_user(path: Path, name: str, role: str, password: str) -> bool:
    """Add or replace ``name`` in the users file (created if missing, mode 0600);
    True when it replaced one."""
    users = list(parse_users_file(path.read_text(encoding="utf-8"), str(path))) if path.exists() else []
    new = entry(name, role, hash_password(password), str(path))
    replaced = any(u.name == name for u in users)
    users = [u for u in users if u.name != name] + [new]
    lines = ["# Users of eskin-bus's OPC UA server and web console "
             "(eskin-bus opcua user add FILE NAME --role reader|operator)", ""]
    for u in users:
        lines += ["[[user]]", f"name = {_toml_str(u.name)}", f"role = {_toml_str(u.role)}",
                  f"password = {_toml_str(u.password)}", ""]
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    os.replace(tmp, path)
    return replaced


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'
