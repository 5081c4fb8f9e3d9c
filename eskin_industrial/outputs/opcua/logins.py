"""Who may connect, and how: the security policies offered, the server's certificate
(made on the first start), the client trust list, the identity tokens (anonymous
where allowed, username and password), the roles' permissions; and what each login,
denial and rejected certificate is counted and logged as."""

from __future__ import annotations

from pathlib import Path

from asyncua import Server, ua

from ...errors import ProfileError
from ..users import Role
from .access import Logins, Permissions
from .options import OpcuaOptions
from .pki import TrustList, certificate_problem, make_certificate, own_paths
from .report import Report
from .users import Directory

_POLICY_TYPES = {
    "None": ua.SecurityPolicyType.NoSecurity,
    "Basic256Sha256_Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "Basic256Sha256_SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
    "Aes128_Sha256_RsaOaep_Sign": ua.SecurityPolicyType.Aes128Sha256RsaOaep_Sign,
    "Aes128_Sha256_RsaOaep_SignAndEncrypt": ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt,
}
_REQUESTS = {ua.ObjectIds.CallRequest_Encoding_DefaultBinary: "Call",
             ua.ObjectIds.WriteRequest_Encoding_DefaultBinary: "Write"}


class LoginSecurity:
    """One server's security, set up in :meth:`certificate`, :meth:`user_manager`
    and :meth:`apply`, in that order, before it starts."""

    def __init__(self, options: OpcuaOptions, users: Directory, report: Report) -> None:
        self.options = options
        self.users = users
        self.report = report
        o = options
        self.anonymous: Role | None = o.anonymous_role if o.anonymous and o.anonymous_role != "none" else None
        self._cert: Path | None = None
        self._key: Path | None = None

    def certificate(self, uri: str) -> str:
        """With a secure policy: the application instance certificate checked, or made
        (then its path is returned)."""
        o = self.options
        if not any(p != "None" for p in o.policies()):
            return ""
        assert o.pki_dir is not None  # OpcuaOptions requires it
        problem = certificate_problem(o.pki_dir, uri)
        if problem is not None:
            raise ProfileError(f"[opcua] {problem}")
        self._cert, self._key = own_paths(o.pki_dir)
        if self._cert.exists():
            return ""
        make_certificate(o.pki_dir, uri, o.application_name, [o.host])
        return str(self._cert)

    def user_manager(self) -> Logins:
        return Logins(self.users, self.anonymous, self._on_login)

    async def apply(self, server: Server) -> None:
        """The identity tokens, the policies with the roles' permissions, the certificate
        and the trust list (after ``server.init()``)."""
        o = self.options
        tokens: list[type] = [ua.UserNameIdentityToken] if self.users.users else []
        if self.anonymous is not None:
            tokens.insert(0, ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        # (asyncua types the ruleset as its SimpleRoleRuleset; any PermissionRuleset is called the same)
        server.set_security_policy([_POLICY_TYPES[p] for p in o.policies()],
                                   permission_ruleset=Permissions(self._on_denied))  # type: ignore[arg-type]
        if self._cert is not None and self._key is not None:
            await server.load_certificate(str(self._cert))
            await server.load_private_key(str(self._key))
            assert o.pki_dir is not None
            server.set_certificate_validator(TrustList(o.pki_dir, self._on_rejected))

    def _on_login(self, user: str, ok: bool) -> None:
        if ok:
            self.report.counts["logins"] += 1
            return
        self.report.counts["logins_refused"] += 1
        self.report.log_once("opcua_login_refused", "warning", user=user)

    def _on_denied(self, user: str, request: int) -> None:
        self.report.counts["denied"] += 1
        self.report.log_once("opcua_access_denied", "warning", user=user,
                             request=_REQUESTS.get(request, str(request)))

    def _on_rejected(self, thumbprint: str, reason: str) -> None:
        self.report.counts["certificates_rejected"] += 1
        assert self.options.pki_dir is not None
        self.report.log_once("opcua_certificate_rejected", "warning", thumbprint=thumbprint, reason=reason,
                             kept=f"{self.options.pki_dir}/rejected/{thumbprint}.der")
