"""Username/password users of the OPC UA server and their roles, from a file or an
environment variable (never from the command line: ``ps`` and the shell's history
would show a password).

The file is TOML, written by ``eskin-bus opcua user add FILE NAME --role ROLE``
(which asks for the password), one table per user, the password as a salted scrypt
hash::

    [[user]]
    name = "scada"
    role = "reader"          # reader: browse, read, subscribe; operator: also methods
    password = "scrypt$16384$8$1$<salt>$<hash>"

The environment variable holds one user a line, ``NAME:ROLE:PASSWORD`` (the password
in clear or as such a hash), for a container or a systemd ``Environment=``.

A login costs one scrypt (0.05 to 0.15 s): a guessing client is slowed, the bridge's
loop is not (the server has its own thread).  A successful login is remembered (a
SHA-256 of the password in memory) so that a client that reconnects pays it once.
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

from .options import Role

ROLES: tuple[Role, ...] = ("reader", "operator")
_SCRYPT = (16384, 8, 1)  #: n, r, p: 16 MB and 0.05 to 0.15 s a hash


@dataclass(frozen=True)
class UserEntry:
    name: str
    role: Role
    #: ``scrypt$N$R$P$SALT$HASH`` (base64), or the password itself (from the environment).
    password: str


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """A salted scrypt hash of ``password`` in the file's form."""
    n, r, p = _SCRYPT
    salt = salt or secrets.token_bytes(16)
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=n, r=r, p=p, maxmem=64 * 1024 * 1024, dklen=32)
    return f"scrypt${n}${r}${p}${_b64(salt)}${_b64(digest)}"


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def verify_password(stored: str, password: str) -> bool:
    """``password`` against a stored hash (or a clear password from the environment)."""
    if not stored.startswith("scrypt$"):
        return hmac.compare_digest(stored.encode("utf-8"), password.encode("utf-8"))
    try:
        _, n, r, p, salt, digest = stored.split("$")
        want = base64.b64decode(digest)
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt), n=int(n), r=int(r), p=int(p),
                             maxmem=64 * 1024 * 1024, dklen=len(want))
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)


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


def _entry(name: object, role: object, password: object, where: str) -> UserEntry:
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
        entry = _entry(u.get("name"), u.get("role"), u.get("password"), where)
        _check_hash(entry.password, where)
        out.append(entry)
    return _unique(out, source)


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
        out.append(_entry(user, role, password, f"users_env: ${name} line {i}"))
    return _unique(out, f"users_env: ${name}")


def _unique(users: list[UserEntry], source: str) -> tuple[UserEntry, ...]:
    seen: set[str] = set()
    for u in users:
        if u.name in seen:
            raise ValueError(f"{source}: user {u.name!r} is given twice")
        seen.add(u.name)
    return tuple(users)


def load_users(users_file: str | None, users_env: str | None) -> tuple[UserEntry, ...]:
    """The configured users (none when neither is set); ValueError ``key: what``."""
    if users_file is not None:
        try:
            text = Path(users_file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise ValueError(f"users_file: {users_file}: cannot read: {reason}") from None
        return parse_users_file(text, f"users_file: {users_file}")
    if users_env is not None:
        value = os.environ.get(users_env)
        if value is None:
            raise ValueError(f"users_env: the environment variable {users_env} is not set")
        return parse_users_env(value, users_env)
    return ()


def add_user(path: Path, name: str, role: str, password: str) -> bool:
    """Add or replace ``name`` in the users file (created if missing, mode 0600);
    True when it replaced one."""
    users = list(parse_users_file(path.read_text(encoding="utf-8"), str(path))) if path.exists() else []
    entry = _entry(name, role, hash_password(password), str(path))
    replaced = any(u.name == name for u in users)
    users = [u for u in users if u.name != name] + [entry]
    lines = ["# OPC UA users of eskin-bus (eskin-bus opcua user add FILE NAME --role reader|operator)", ""]
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
            verify_password(_DUMMY, password)
            return None
        quick = hashlib.sha256(password.encode("utf-8")).digest()
        known = self._remembered.get(name)
        if known is not None and hmac.compare_digest(known, quick):
            return user.role
        if not verify_password(user.password, password):
            return None
        self._remembered[name] = quick
        return user.role


_DUMMY = "scrypt$16384$8$1$AAAAAAAAAAAAAAAAAAAAAA==$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA="
