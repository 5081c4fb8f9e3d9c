"""``eskin-bus opcua``: the OPC UA output's tools: the type model as NodeSet2, the
server's certificate, the trust list, the users file."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click


@click.group()
def opcua() -> None:
    """The OPC UA output: its NodeSet2, certificate, trusted clients and users
    (docs/opcua.md)."""


@opcua.command("nodeset")
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False, writable=True), required=True,
              help="The NodeSet2 XML file to write.")
def nodeset_cmd(output: str) -> None:
    """Write the type model (GraspStateEnumeration, GraspSensorType, SlipAlarmType, in
    the namespace urn:eskin-industrial:opcua:grasp) as a NodeSet2 XML file, for an
    engineering tool or another OPC UA stack to import."""
    from ..outputs.opcua.nodeset import write_nodeset
    from ..outputs.opcua.sink import need_asyncua

    need_asyncua("eskin-bus opcua nodeset")
    _check_folder(output, "--output")
    write_nodeset(output)
    click.echo(f"wrote {output}", err=True)


def _check_folder(path: str, flag: str) -> None:
    folder = Path(path).parent
    if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
        raise click.BadParameter(f"{path}: {str(folder)!r} is not a writable folder", param_hint=flag)


def _options(config: str | None, pki_dir: str | None, endpoint: str | None) -> tuple[str, str, str, str]:
    """(pki_dir, application URI, application name, endpoint host) from a bridge
    configuration's [opcua] or the options."""
    from ..outputs.opcua.options import OpcuaOptions, parse_endpoint_url
    from ..outputs.opcua.pki import default_application_uri

    if config is not None:
        if pki_dir is not None or endpoint is not None:
            raise click.UsageError("--pki-dir/--endpoint: with --config the file gives them")
        from ..bridge.config import load_bridge_config

        options = load_bridge_config(config).outputs.get("opcua")
        if not isinstance(options, OpcuaOptions):
            raise click.BadParameter(f"{config}: no [opcua] section", param_hint="--config")
        if options.pki_dir is None:
            raise click.BadParameter(f"{config}: [opcua] pki_dir is not set", param_hint="--config")
        return (options.pki_dir, options.application_uri or default_application_uri(), options.application_name,
                options.host)
    if pki_dir is None:
        raise click.UsageError("give --pki-dir DIR (and --endpoint URL), or --config bridge.toml")
    try:
        host = parse_endpoint_url(endpoint)[0] if endpoint else "127.0.0.1"
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--endpoint") from None
    return pki_dir, default_application_uri(), OpcuaOptions.application_name, host


@opcua.command("cert")
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Take pki_dir, the application URI and name, and the endpoint's host from this bridge "
                   "configuration's [opcua].")
@click.option("--pki-dir", default=None, metavar="DIR", help="The certificates' folder (without --config).")
@click.option("--endpoint", default=None, metavar="URL",
              help="The server's endpoint, opc.tcp://HOST:PORT: its host goes in the certificate (without --config).")
@click.option("--force", is_flag=True, help="Replace a certificate already there (clients must trust the new one).")
def cert_cmd(config: str | None, pki_dir: str | None, endpoint: str | None, force: bool) -> None:
    """Make the server's application instance certificate and its key (RSA 2048,
    SHA-256, five years; the application URI and the hosts in its subject alternative
    name) in PKI_DIR/own, and the trusted/ and rejected/ folders.  The bridge makes
    one on its first start when there is none; this makes it before, to hand to the
    clients' administrators."""
    from ..outputs.opcua.pki import make_certificate, own_paths, thumbprint
    from ..outputs.opcua.sink import need_asyncua

    need_asyncua("eskin-bus opcua cert")
    pki, uri, name, host = _options(config, pki_dir, endpoint)
    cert, _key = own_paths(pki)
    if cert.exists() and not force:
        raise click.UsageError(f"{cert} exists: --force replaces it (every client must then trust the new one)")
    try:
        made = make_certificate(pki, uri, name, [host])
    except OSError as exc:
        raise click.BadParameter(f"{pki}: {exc.strerror or exc}", param_hint="--pki-dir") from None
    click.echo(f"{made}  thumbprint {thumbprint(made.read_bytes())}  {uri}")


@opcua.command("trust")
@click.option("--pki-dir", required=True, metavar="DIR", help="The certificates' folder ([opcua] pki_dir).")
@click.argument("thumbprint", required=False)
def trust_cmd(pki_dir: str, thumbprint: str | None) -> None:
    """Without THUMBPRINT: list the client certificates the server refused
    (PKI_DIR/rejected) and those it trusts.  With it: move that refused certificate to
    trusted/ (the client's next connection is accepted; no restart)."""
    rejected, trusted = Path(pki_dir) / "rejected", Path(pki_dir) / "trusted"
    if thumbprint is None:
        for label, folder in (("rejected", rejected), ("trusted", trusted)):
            files = sorted(folder.glob("*")) if folder.is_dir() else []
            for f in files:
                click.echo(f"{label}  {f.name}  {_subject(f)}")
        return
    matches = [p for p in (rejected.glob(f"{thumbprint.lower()}*") if rejected.is_dir() else [])]
    if len(matches) != 1:
        raise click.BadParameter(f"{thumbprint}: {'no' if not matches else 'more than one'} certificate of that "
                                 f"thumbprint in {rejected}", param_hint="THUMBPRINT")
    trusted.mkdir(parents=True, exist_ok=True)
    target = trusted / matches[0].name
    matches[0].replace(target)
    click.echo(f"trusted {target}")


def _subject(path: Path) -> str:
    try:
        from cryptography import x509

        data = path.read_bytes()
        try:
            cert = x509.load_der_x509_certificate(data)
        except ValueError:
            cert = x509.load_pem_x509_certificate(data)
        return cert.subject.rfc4514_string()
    except (ImportError, OSError, ValueError):
        return "(not a certificate)"


@opcua.group("user")
def user() -> None:
    """The users file ([opcua] users_file)."""


@user.command("add")
@click.argument("file", type=click.Path(dir_okay=False))
@click.argument("name")
@click.option("--role", type=click.Choice(["reader", "operator"]), required=True,
              help="reader: browse, read, subscribe, events; operator: also the methods (Tare, AcknowledgeSlip, "
                   "Enable, the alarm's Acknowledge).")
def user_add(file: str, name: str, role: str) -> None:
    """Add NAME to the users FILE (made if missing, mode 0600), or replace its
    password and role.  The password is asked for on a terminal, or read from the
    first line of standard input; it is stored as a salted scrypt hash.  No option
    takes the password: the command line shows in ps and the shell's history."""
    from ..outputs.opcua.users import add_user

    if sys.stdin.isatty():
        password = click.prompt("password", hide_input=True, confirmation_prompt=True)
    else:
        password = sys.stdin.readline().rstrip("\r\n")
    if not password:
        raise click.BadParameter("an empty password", param_hint="password")
    try:
        replaced = add_user(Path(file), name, role, password)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="FILE") from None
    except OSError as exc:
        raise click.BadParameter(f"{file}: {exc.strerror or exc}", param_hint="FILE") from None
    click.echo(f"{'replaced' if replaced else 'added'} {name} ({role}) in {file}", err=True)
