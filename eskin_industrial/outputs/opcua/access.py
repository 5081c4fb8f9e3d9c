"""Who may do what: the sessions' users and their roles, in asyncua's two hooks.

- :class:`Logins` (asyncua's user manager) turns an ActivateSession's identity into a
  user with a role: a username and password checked against the users
  (:mod:`.users`), or an anonymous session (offered only where anonymous access is
  allowed: :attr:`.options.OpcuaOptions.anonymous`).
- :class:`Permissions` (asyncua's permission ruleset, asked before every request):
  a ``reader`` browses, reads, subscribes and receives events; an ``operator`` may
  also call methods (Tare, AcknowledgeSlip, Enable, the alarm's Acknowledge).  Writes
  are no one's: every variable is read-only, and a Write is refused for a reader
  before it reaches the address space.  A refused request is answered
  BadUserAccessDenied.
"""

from __future__ import annotations

from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from asyncua import ua
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole
from asyncua.server.user_managers import UserManager

from ..users import Role
from .uaconv import node_id
from .users import Directory

_READER = frozenset(node_id(t) for t in USER_TYPES
                    if t not in (ua.ObjectIds.CallRequest_Encoding_DefaultBinary,
                                 ua.ObjectIds.WriteRequest_Encoding_DefaultBinary))
_OPERATOR = frozenset(node_id(t) for t in USER_TYPES)
#: The user of the request being served (its name, or ``anonymous``): asyncua hands a
#: method no session, and the alarm's comments name who made them (ClientUserId).  Set
#: as each request is allowed, in the task that then serves it.
REQUEST_USER: ContextVar[str] = ContextVar("opcua_request_user", default="")


@dataclass
class RoleUser(User):
    """A session's user with its role (``reader`` or ``operator``)."""

    access: Role = "reader"


class Permissions(PermissionRuleset):
    """Requests by role; ``on_denied(user, request type)`` hears of each refusal."""

    def __init__(self, on_denied: Callable[[str, int], None]) -> None:
        self.on_denied = on_denied

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        access = getattr(user, "access", None)
        allowed = _OPERATOR if access == "operator" else _READER if access == "reader" else frozenset()
        if action_type_id in allowed:
            REQUEST_USER.set(getattr(user, "name", None) or "anonymous")
            return True
        self.on_denied(getattr(user, "name", None) or "anonymous", int(action_type_id.Identifier))
        return False


class Logins(UserManager):
    """Identities to users; ``on_login(name, ok)`` hears of each attempt."""

    def __init__(self, directory: Directory, anonymous_role: Role | None,
                 on_login: Callable[[str, bool], None]) -> None:
        self.directory = directory
        self.anonymous_role = anonymous_role
        self.on_login = on_login

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if username is None:
            if self.anonymous_role is None:  # (the token is not offered then: asyncua refuses it first)
                self.on_login("anonymous", False)
                return None
            self.on_login("anonymous", True)
            return RoleUser(role=UserRole.User, name=None, access=self.anonymous_role)
        role = self.directory.login(username, password or "")
        self.on_login(username, role is not None)
        if role is None:
            return None
        return RoleUser(role=UserRole.User, name=username, access=role)
