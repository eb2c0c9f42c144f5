"""The deployment's keystore: one CA and one certificate + key per identity, in one directory.

The router admits a session only with a certificate the deployment's CA signed, and its rules
(runtime/security/acl.py) know the process by the certificate's common name: a service's name, a
side's (`router`, `robot`, `workstation`) or `tools`. Keys are mode 0600 in a 0700 directory: a key
is the identity. A certificate is bound to the robots it may act for (a subject alternative name
`urn:beyond-self:<role>:<robots>`), so a key stolen from one robot speaks for that robot alone; one
made before bindings existed is read as its own name's role on every robot. A bad certificate is
one line here naming the file, not an error deep in Zenoh's link layer.
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from beyond_self.core.errors import InputError
from beyond_self.runtime.security.acl import Binding
from beyond_self.schemas.keys import DEFAULT_ROBOT, check_name, robot_pattern

CA = "ca"
TOOLS = "tools"
DEFAULT_DAYS = 365
CA_DAYS = 3650
_KEY_MODE = 0o600
_DIR_MODE = 0o700
# TLS wants a subject alternative name on a listener's certificate; host names are not verified
# on this bus (runtime/security/secure.py: identities are common names), so any certificate may
# serve.
_SAN = ["localhost"]
_BINDING = "urn:beyond-self:"  # urn:beyond-self:<role>:<robots pattern>


def _binding_uri(binding: Binding) -> str:
    return f"{_BINDING}{binding.role}:{binding.robots}"


def binding_of(cert: x509.Certificate, name: str) -> Binding:
    """The binding a certificate carries (its own name's role on every robot if none)."""
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return Binding(name, "*")
    for uri in san.get_values_for_type(x509.UniformResourceIdentifier):
        if uri.startswith(_BINDING):
            role, _, robots = uri[len(_BINDING) :].partition(":")
            return Binding(role, robots)
    return Binding(name, "*")


@dataclass(frozen=True)
class Entry:
    """One certificate in the keystore, as `beyond keys show` lists it."""

    name: str
    path: Path
    not_after: dt.datetime
    issuer: str
    binding: Binding | None = None  # None for the CA

    @property
    def expired(self) -> bool:
        return self.not_after <= _now()


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def cert_path(directory: Path, name: str) -> Path:
    return directory / f"{name}.crt"


def key_path(directory: Path, name: str) -> Path:
    return directory / f"{name}.key"


def _write(path: Path, data: bytes, mode: int) -> None:
    """Write with the final mode from the first byte on (never briefly world-readable)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)
    os.chmod(path, mode)


def _new_key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _key_bytes(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _name(common_name: str) -> x509.Name:
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "beyond-self"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


_KEY_USAGES = (
    "digital_signature",
    "content_commitment",
    "key_encipherment",
    "data_encipherment",
    "key_agreement",
    "key_cert_sign",
    "crl_sign",
    "encipher_only",
    "decipher_only",
)


def _key_usage(*allowed: str) -> x509.KeyUsage:
    """The key usage extension allowing only `allowed` (x509 wants every usage named)."""
    return x509.KeyUsage(**{usage: usage in allowed for usage in _KEY_USAGES})


def init(
    directory: Path, names: list[str], *, days: int = DEFAULT_DAYS, robots: str = DEFAULT_ROBOT
) -> list[Path]:
    """A new CA in `directory` (which must not hold one) and a certificate for each name, each
    bound to `robots` (a robot name or pattern) in its own name's role."""
    if cert_path(directory, CA).exists() or key_path(directory, CA).exists():
        raise InputError(
            f"{directory} already holds a CA ({cert_path(directory, CA)}); "
            "add identities with `beyond keys add NAME` or choose an empty directory"
        )
    directory.mkdir(parents=True, exist_ok=True)
    os.chmod(directory, _DIR_MODE)
    key = _new_key()
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name("beyond-self CA"))
        .issuer_name(_name("beyond-self CA"))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=CA_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage("digital_signature", "key_cert_sign", "crl_sign"), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    _write(key_path(directory, CA), _key_bytes(key), _KEY_MODE)
    _write(cert_path(directory, CA), cert.public_bytes(serialization.Encoding.PEM), 0o644)
    written = [cert_path(directory, CA)]
    for name in names:
        written.append(add(directory, name, days=days, robots=robots))
    return written


def _load_ca(directory: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    cert = load_certificate(cert_path(directory, CA))
    path = key_path(directory, CA)
    if not path.is_file():
        raise InputError(
            f"{path}: missing (the CA key signs new identities; run `beyond keys init`)"
        )
    key = serialization.load_pem_private_key(path.read_bytes(), password=None)
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise InputError(f"{path}: not an EC private key made by `beyond keys init`")
    return cert, key


def add(
    directory: Path,
    name: str,
    *,
    days: int = DEFAULT_DAYS,
    not_before: dt.datetime | None = None,
    role: str | None = None,
    robots: str = DEFAULT_ROBOT,
) -> Path:
    """A certificate + key for identity `name`, signed by the keystore's CA (replacing any),
    bound to acting as `role` (default: its own name) for the robots `robots` matches."""
    check_name("identity", name)
    if name == CA:
        raise InputError(f"identity name {CA!r} is the CA's own; choose another")
    binding = Binding(check_name("role", role or name), robot_pattern(robots))
    if not 0 < days <= CA_DAYS:
        raise InputError(f"validity of {days} days; valid: 1-{CA_DAYS}")
    ca_cert, ca_key = _load_ca(directory)
    key = _new_key()
    start = not_before or _now() - dt.timedelta(minutes=5)
    end = start + dt.timedelta(days=days)
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.SubjectAlternativeName(
                [
                    *[x509.DNSName(n) for n in [*_SAN, name]],
                    x509.UniformResourceIdentifier(_binding_uri(binding)),
                ]
            ),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
        .sign(ca_key, hashes.SHA256())
    )
    _write(key_path(directory, name), _key_bytes(key), _KEY_MODE)
    path = cert_path(directory, name)
    _write(path, cert.public_bytes(serialization.Encoding.PEM), 0o644)
    return path


def load_certificate(path: Path) -> x509.Certificate:
    if not path.is_file():
        raise InputError(f"{path}: missing (make it with `beyond keys init` or `beyond keys add`)")
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        raise InputError(f"{path}: not a PEM certificate") from None


def _common_name(subject: x509.Certificate | x509.Name) -> str:
    name = subject.subject if isinstance(subject, x509.Certificate) else subject
    values = name.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(values[0].value) if values else ""


def show(directory: Path) -> list[Entry]:
    """Every certificate in the keystore, the CA first, with its expiry."""
    if not directory.is_dir():
        raise InputError(f"keystore {directory} does not exist; make one with `beyond keys init`")
    entries = []
    paths = sorted(directory.glob("*.crt"), key=lambda p: (p.stem != CA, p.stem))
    for path in paths:
        cert = load_certificate(path)
        name = _common_name(cert) if path.stem != CA else CA
        entries.append(
            Entry(
                name=name,
                path=path,
                not_after=cert.not_valid_after_utc,
                issuer=_common_name(cert.issuer),
                binding=binding_of(cert, name) if name != CA else None,
            )
        )
    return entries


def bindings(directory: Path) -> dict[str, Binding]:
    """Every identity of the keystore and its binding: the subjects of the router's rules."""
    return {e.name: e.binding for e in show(directory) if e.binding is not None}


def check(directory: Path, name: str) -> tuple[Path, Path, Path]:
    """(CA, certificate, key) of identity `name`, each checked: present, readable, the
    certificate current, issued to `name`, signed by this keystore's CA and matching its key.
    Raises InputError naming the file and what is wrong."""
    if not directory.is_dir():
        raise InputError(f"keystore {directory}: missing (make one with `beyond keys init`)")
    ca_file = cert_path(directory, CA)
    ca = load_certificate(ca_file)
    _check_dates(ca_file, ca)
    cert_file, key_file = cert_path(directory, name), key_path(directory, name)
    cert = load_certificate(cert_file)
    _check_dates(cert_file, cert)
    if _common_name(cert) != name:
        raise InputError(
            f"{cert_file}: issued to {_common_name(cert)!r}, not {name!r} "
            f"(remake it with `beyond keys add {name}`)"
        )
    try:
        cert.verify_directly_issued_by(ca)
    except (InvalidSignature, TypeError, ValueError):
        raise InputError(
            f"{cert_file}: not signed by this deployment's CA ({ca_file}); "
            f"remake it with `beyond keys add {name}`"
        ) from None
    if not key_file.is_file():
        raise InputError(f"{key_file}: missing (remake it with `beyond keys add {name}`)")
    try:
        key = serialization.load_pem_private_key(key_file.read_bytes(), password=None)
    except (ValueError, TypeError, OSError):
        raise InputError(f"{key_file}: not an unencrypted PEM private key") from None
    if key.public_key() != cert.public_key():
        raise InputError(f"{key_file}: does not belong to {cert_file}")
    return ca_file, cert_file, key_file


def _check_dates(path: Path, cert: x509.Certificate) -> None:
    now = _now()
    if cert.not_valid_after_utc <= now:
        raise InputError(
            f"{path}: expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC "
            f"(renew it with `beyond keys add {path.stem}`)"
        )
    if cert.not_valid_before_utc > now:
        raise InputError(f"{path}: not valid before {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC")
