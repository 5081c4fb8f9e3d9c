"""The server's certificates: its application instance certificate, the clients it
trusts, the ones it refused.

``pki_dir`` holds, in the layout OPC UA stacks share (node-opcua, the UA .NET stack)::

    own/cert.der           the application instance certificate (DER), made on first
                           start or by `eskin-bus opcua cert`
    own/private/key.pem    its private key (PEM, mode 0600)
    trusted/               the client certificates this server trusts (DER or PEM)
    rejected/              certificates a client presented and the server refused,
                           THUMBPRINT.der: move one to trusted/ to trust that client

The trust list is read again at each session a client opens, so that a certificate
moved into ``trusted/`` counts from the next connection, without a restart.
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import ipaddress
import os
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ...errors import OutputFileError

#: Certificates kept in ``rejected/`` at most (a client that presents a new one at
#: every connection must not fill the disk); past it they are counted, not stored.
REJECTED_MAX = 100
CERT_DAYS = 5 * 365


def own_paths(pki_dir: str | Path) -> tuple[Path, Path]:
    """(the certificate, its private key) under ``pki_dir``."""
    pki = Path(pki_dir)
    return pki / "own" / "cert.der", pki / "own" / "private" / "key.pem"


def default_application_uri() -> str:
    return f"urn:{socket.gethostname()}:eskin-industrial:bridge"


def thumbprint(der: bytes) -> str:
    """The certificate's SHA-1 thumbprint in hex (OPC UA's name for a certificate)."""
    return hashlib.sha1(der).hexdigest()


def make_certificate(pki_dir: str | Path, application_uri: str, name: str, hosts: list[str],
                     days: int = CERT_DAYS) -> Path:
    """A new key and self-signed application instance certificate (RSA 2048, SHA-256,
    the URI and the hosts in its subject alternative name), replacing what ``own/``
    held; the folders are made.  Returns the certificate's path."""
    from asyncua.crypto.cert_gen import generate_private_key, generate_self_signed_app_certificate
    from asyncua.crypto.uacrypto import pem_from_key
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    cert_path, key_path = own_paths(pki_dir)
    try:
        for d in (cert_path.parent, key_path.parent, Path(pki_dir) / "trusted", Path(pki_dir) / "rejected"):
            d.mkdir(parents=True, exist_ok=True)
        os.chmod(key_path.parent, 0o700)
    except OSError as exc:
        raise OutputFileError(f"pki_dir: {pki_dir}: cannot make its folders: "
                              f"{(exc.strerror or str(exc)).lower()}") from None
    key = generate_private_key()
    alt: list[x509.GeneralName] = [x509.UniformResourceIdentifier(application_uri)]
    for host in dict.fromkeys([*hosts, socket.gethostname()]):
        try:
            address = ipaddress.ip_address(host)
        except ValueError:
            alt.append(x509.DNSName(host))
            continue
        if not address.is_unspecified:  # 0.0.0.0 and :: are every interface, no address of its own
            alt.append(x509.IPAddress(address))
    cert = generate_self_signed_app_certificate(key, name, {"organizationName": "eskin-industrial"}, alt,
                                                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
                                                days=days)
    # Both written beside their place, then renamed (a rename needs no room): a full
    # disk leaves the old pair or none, never a key without its certificate or a
    # certificate cut short (which the next start would refuse).
    written: list[Path] = []
    try:
        for data, path, mode in ((pem_from_key(key), key_path, 0o600),
                                 (cert.public_bytes(serialization.Encoding.DER), cert_path, 0o644)):
            tmp = path.with_name(path.name + ".tmp")
            written.append(tmp)
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        os.replace(written[0], key_path)
        os.replace(written[1], cert_path)
    except OSError as exc:
        for tmp in written:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise OutputFileError(f"pki_dir: {pki_dir}: cannot write the certificate: "
                              f"{(exc.strerror or str(exc)).lower()}") from None
    return cert_path


def certificate_problem(pki_dir: str | Path, application_uri: str) -> str | None:
    """What is wrong with ``own/`` for this server (None: nothing, or nothing there
    yet: it is made at start).  ``key: what`` lines, as ``--check`` prints them."""
    cert_path, key_path = own_paths(pki_dir)
    if not cert_path.exists() and not key_path.exists():
        return _writable_problem(Path(pki_dir))
    for p in (cert_path, key_path):
        if not p.is_file() or not os.access(p, os.R_OK):
            return f"pki_dir: {p}: {'not readable' if p.exists() else 'missing'} (eskin-bus opcua cert makes both)"
    cert = _load_certificate(cert_path.read_bytes())
    if cert is None:
        return f"pki_dir: {cert_path}: not a certificate (DER or PEM)"
    from cryptography import x509

    try:
        uris = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value.get_values_for_type(
            x509.UniformResourceIdentifier)
    except x509.ExtensionNotFound:
        uris = []
    if application_uri not in uris:
        return (f"pki_dir: {cert_path}: the certificate is for {', '.join(uris) or 'no URI'}, not {application_uri!r} "
                f"(eskin-bus opcua cert --force makes a new one)")
    if cert.not_valid_after_utc < datetime.datetime.now(datetime.UTC):
        return f"pki_dir: {cert_path}: expired on {cert.not_valid_after_utc:%Y-%m-%d} (eskin-bus opcua cert --force)"
    return None


def _writable_problem(pki: Path) -> str | None:
    d = pki
    while not d.exists() and d != d.parent:  # made at start: its first existing parent
        d = d.parent
    if not d.is_dir() or not os.access(d, os.W_OK | os.X_OK):
        return f"pki_dir: {str(pki)!r}: {str(d)!r} is not a writable folder (the certificate is made there)"
    return None


def _load_certificate(data: bytes) -> Any:
    from cryptography import x509

    try:
        return x509.load_der_x509_certificate(data)
    except ValueError:
        pass
    try:
        return x509.load_pem_x509_certificate(data)
    except ValueError:
        return None


class TrustList:
    """Judges a client's certificate when it opens a session (the server's thread):
    valid now, its URI the client's application URI, and in ``trusted/``; a refused
    one is kept in ``rejected/`` and reported through ``on_reject(thumbprint, reason)``."""

    def __init__(self, pki_dir: str | Path, on_reject: Callable[[str, str], None]) -> None:
        self.trusted_dir = Path(pki_dir) / "trusted"
        self.rejected_dir = Path(pki_dir) / "rejected"
        self.on_reject = on_reject
        self.rejected = 0

    def trusted(self) -> set[bytes]:
        """The DER of every certificate in ``trusted/`` (read at each call)."""
        out: set[bytes] = set()
        try:
            files = [p for p in self.trusted_dir.iterdir() if p.is_file()]
        except OSError:
            return out
        for p in files:
            try:
                cert = _load_certificate(p.read_bytes())
            except OSError:
                continue
            if cert is not None:
                from cryptography.hazmat.primitives import serialization

                out.add(cert.public_bytes(serialization.Encoding.DER))
        return out

    async def __call__(self, cert: Any, app_description: Any) -> None:
        """asyncua's certificate validator hook: returns, or raises its ServiceError."""
        from asyncua import ua
        from asyncua.common.utils import ServiceError
        from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
        from cryptography.hazmat.primitives import serialization

        der = cert.public_bytes(serialization.Encoding.DER)
        try:
            await CertificateValidator(CertificateValidatorOptions.BASIC_VALIDATION
                                       | CertificateValidatorOptions.PEER_CLIENT).validate(cert, app_description)
        except ServiceError as exc:
            self._reject(der, ua.StatusCode(ua.UInt32(exc.code)).name)
            raise
        if der not in self.trusted():
            self._reject(der, "BadCertificateUntrusted")
            raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)

    def _reject(self, der: bytes, reason: str) -> None:
        self.rejected += 1
        name = thumbprint(der)
        try:
            self.rejected_dir.mkdir(parents=True, exist_ok=True)
            target = self.rejected_dir / f"{name}.der"
            if not target.exists() and sum(1 for _ in self.rejected_dir.iterdir()) < REJECTED_MAX:
                target.write_bytes(der)
        except OSError:
            pass  # the refusal stands; the event says which certificate
        self.on_reject(name, reason)
