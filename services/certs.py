"""onebox certs: a certificate authority and one certificate a process, for config/secure/.

Writes into DIR (made if missing, files never overwritten):

  ca.pem, ca.key            the test deployment's own certificate authority (keep ca.key apart)
  NAME.pem, NAME.key        one certificate a process, its common name NAME: router, sim,
                            locator, points, viewer, record, snapshot, check, pixels, replay,
                            echo, hz, bw, pub and any --name given

The router's access control (config/secure/router.json5) knows each process by its
certificate's common name; a process finds its own as DIR/<its command>.pem when run with
``--secure DIR`` or ``ONEBOX_SECURE=DIR``. Every certificate names localhost and 127.0.0.1, and
each --host (an address or a DNS name another host's router is reached at). For a test
deployment: a real one gets its certificates from its own authority.
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import logging
import os
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from onebox.errors import SettingError

log = logging.getLogger("certs")

IDENTITIES = (
    "router",
    "sim",
    "locator",
    "points",
    "viewer",
    "record",
    "snapshot",
    "check",
    "pixels",
    "replay",
    "echo",
    "hz",
    "bw",
    "pub",
)
"""Every onebox command that opens the bus: the secured router's access control names them."""


@dataclass(frozen=True)
class CertSettings:
    folder: Path
    names: tuple[str, ...]
    hosts: tuple[str, ...]
    days: int


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, metavar="DIR", help="where to write the files")
    parser.add_argument(
        "--name",
        action="append",
        default=[],
        help="one more identity (a certificate with this common name), repeatable",
    )
    parser.add_argument(
        "--host",
        action="append",
        default=[],
        help="one more address or DNS name every certificate is valid for, repeatable",
    )
    parser.add_argument("--days", type=int, default=365, help="validity (default 365)")


def main(args: argparse.Namespace) -> int:
    """Make the authority and the certificates."""
    names = tuple(dict.fromkeys([*IDENTITIES, *args.name]))
    settings = CertSettings(args.folder, names, tuple(args.host), args.days)
    if settings.days <= 0:
        raise SettingError(f"--days {settings.days}: must be above 0")
    for name in settings.names:
        if not name or "/" in name or name.startswith("."):
            raise SettingError(f"--name {name!r}: use a plain name such as arm or stranger")
    make_certificates(settings)
    log.info("wrote %s and %d certificates into %s", "ca.pem", len(names), settings.folder)
    return 0


def make_certificates(settings: CertSettings) -> None:
    """ca.pem/ca.key and NAME.pem/NAME.key for every name, into ``settings.folder``."""
    folder = settings.folder
    folder.mkdir(parents=True, exist_ok=True)
    existing = [
        p for p in [folder / "ca.pem", *(folder / f"{n}.pem" for n in settings.names)] if p.exists()
    ]
    if existing:
        raise SettingError(
            f"{existing[0]} already exists: choose another DIR or remove the old certificates"
        )
    now = datetime.datetime.now(datetime.UTC)
    until = now + datetime.timedelta(days=settings.days)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "onebox test CA")])
    ca = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(until)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(ca_key, hashes.SHA256())
    )
    _write(folder / "ca.key", _key_pem(ca_key))
    _write(folder / "ca.pem", ca.public_bytes(serialization.Encoding.PEM))
    alt_names = _alt_names(("localhost", "127.0.0.1", *settings.hosts))
    for name in settings.names:
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName(alt_names), critical=False)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
            .sign(ca_key, hashes.SHA256())
        )
        _write(folder / f"{name}.key", _key_pem(key))
        _write(folder / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM))


def _alt_names(hosts: tuple[str, ...]) -> list[x509.GeneralName]:
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys(hosts):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _write(path: Path, data: bytes) -> None:
    """Write ``data``; a private key is readable by its owner only."""
    mode = 0o600 if path.suffix == ".key" else 0o644
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
