"""A small private certificate authority for one fleet: make it, issue certificates, read them.

A directory holds the CA (``ca.pem``, and ``ca.key`` mode 600) and, per member, ``NAME.pem`` and
``NAME.key`` (mode 600). A member's certificate carries its name as the subject's common name
(Zenoh's access control matches on it) and its role as the organizational unit, plus subject
alternative names (Zenoh's TLS checks the host a peer connects to against them: by default the
name, ``localhost`` and ``127.0.0.1``). Keys are EC P-256; the cryptography is the
``cryptography`` library's, none of it is made here. Every problem is a one-line
:class:`~companion.errors.UserError` naming the file.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import re
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from ..errors import UserError
from ..secretfile import read_private
from .roles import ROLES

CA_CERT, CA_KEY = "ca.pem", "ca.key"
ORGANIZATION = "pzc-rover fleet"
# A name becomes one chunk of the key rover/<name>/... and a file name: no wildcards, no '/'.
_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
_HOST = re.compile(r"^(?=.{1,253}$)([A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)"
                   r"(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$")
DEFAULT_SANS = ("localhost", "127.0.0.1")
MAX_PEM_BYTES = 64 * 1024             # a certificate or key is a few hundred bytes
CLOCK_SKEW = dt.timedelta(minutes=5)  # valid from a little before now: clocks differ


@dataclass(frozen=True)
class CertInfo:
    """What a certificate says, as ``companion pki show`` prints it."""

    path: Path
    name: str                   # the subject's common name
    role: str | None            # the subject's organizational unit, when it is one of ROLES
    issuer: str                 # the issuer's common name
    not_before: dt.datetime     # UTC
    not_after: dt.datetime      # UTC
    sans: tuple[str, ...]
    fingerprint: str            # SHA-256 of the DER certificate, hex
    is_ca: bool

    def problem(self, now: dt.datetime | None = None) -> str | None:
        """Why the certificate is not valid now (expired, not yet valid), or None."""
        now = now or utcnow()
        if now > self.not_after:
            return f"expired on {stamp(self.not_after)}"
        if now < self.not_before:
            return f"not valid before {stamp(self.not_before)}"
        return None


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def stamp(t: dt.datetime) -> str:
    return t.strftime("%Y-%m-%d %H:%M:%S UTC")


def check_name(name: str) -> str:
    if not _NAME.match(name) or name in ("ca", ".", ".."):
        raise UserError(f"name {name!r}: use 1-64 letters, digits, '_', '-' or '.', not 'ca' "
                        "(a rover's name is its vehicle id, the <id> in rover/<id>/...)")
    return name


def check_role(role: str) -> str:
    if role not in ROLES:
        raise UserError(f"role {role!r}: one of {', '.join(ROLES)}")
    return role


def _san(text: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(text))
    except ValueError:
        pass
    if not _HOST.match(text):
        raise UserError(f"--san {text!r}: not a host name or an IP address")
    return x509.DNSName(text.lower())


# --------------------------------------------------------------------------- reading

def load_cert(path: Path, what: str = "certificate") -> x509.Certificate:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        return x509.load_pem_x509_certificate(data)
    except ValueError:
        raise UserError(f"{path}: not a PEM {what}") from None


def load_key(path: Path, flag: str) -> ec.EllipticCurvePrivateKey:
    """A private key, after the file passed the owner-only check (``flag`` names who asked)."""
    data = read_private(str(path), flag, "private key", MAX_PEM_BYTES)
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError):
        raise UserError(f"{flag} {path}: not an unencrypted PEM private key") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise UserError(f"{flag} {path}: not an EC private key")
    return key


def info(cert: x509.Certificate, path: Path) -> CertInfo:
    def attr(name: x509.Name, oid) -> str:
        values = name.get_attributes_for_oid(oid)
        return str(values[0].value) if values else ""
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        sans = tuple(str(v) for v in san.get_values_for_type(x509.DNSName)) + tuple(
            str(v) for v in san.get_values_for_type(x509.IPAddress))
    except x509.ExtensionNotFound:
        sans = ()
    try:
        is_ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = False
    role = attr(cert.subject, NameOID.ORGANIZATIONAL_UNIT_NAME)
    return CertInfo(
        path=path, name=attr(cert.subject, NameOID.COMMON_NAME),
        role=role if role in ROLES and not is_ca else None,
        issuer=attr(cert.issuer, NameOID.COMMON_NAME),
        not_before=cert.not_valid_before_utc, not_after=cert.not_valid_after_utc, sans=sans,
        fingerprint=cert.fingerprint(hashes.SHA256()).hex(), is_ca=is_ca)


def issued_by(cert: x509.Certificate, ca: x509.Certificate) -> bool:
    """The CA signed this certificate (issuer name and signature both check)."""
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        return False
    return True


def same_key(cert: x509.Certificate, key: ec.EllipticCurvePrivateKey) -> bool:
    der = serialization.Encoding.DER
    spki = serialization.PublicFormat.SubjectPublicKeyInfo
    return cert.public_key().public_bytes(der, spki) == key.public_key().public_bytes(der, spki)


# --------------------------------------------------------------------------- writing

def _write(path: Path, data: bytes, mode: int) -> None:
    """Create ``path`` with ``mode`` from the first byte (a key is never readable by others,
    not even for an instant); an existing file is replaced."""
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    try:
        os.fchmod(fd, mode)          # the umask may only have narrowed it; say it exactly
        os.write(fd, data)
    finally:
        os.close(fd)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    # Unencrypted: Zenoh reads the key file itself and takes no passphrase. Mode 600 guards it.
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _cert_pem(cert: x509.Certificate) -> bytes:
    return cert.public_bytes(serialization.Encoding.PEM)


def init_ca(directory: Path, days: int = 3650, common_name: str | None = None,
            now: dt.datetime | None = None) -> CertInfo:
    """Make ``directory`` (mode 700 when new) and a self-signed CA in it; never replaces one."""
    ca_cert, ca_key = directory / CA_CERT, directory / CA_KEY
    if ca_cert.exists() or ca_key.exists():
        raise UserError(f"{directory} already holds a CA ({CA_CERT}, {CA_KEY}): refusing to "
                        "replace it (every certificate it issued would stop working)")
    try:
        directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{directory}: cannot create: {exc.strerror}") from None
    now = now or utcnow()
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([
        x509.NameAttribute(NameOID.COMMON_NAME,
                           common_name or f"pzc-rover fleet CA ({directory.resolve().name})"),
        x509.NameAttribute(NameOID.ORGANIZATION_NAME, ORGANIZATION)])
    cert = (x509.CertificateBuilder()
            .subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - CLOCK_SKEW).not_valid_after(now + dt.timedelta(days=days))
            # path_length 0: it signs members' certificates, never another CA.
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(
                digital_signature=False, content_commitment=False, key_encipherment=False,
                data_encipherment=False, key_agreement=False, key_cert_sign=True, crl_sign=True,
                encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False)
            .sign(key, hashes.SHA256()))
    try:
        _write(ca_key, _key_pem(key), 0o600)
        _write(ca_cert, _cert_pem(cert), 0o644)
    except OSError as exc:
        raise UserError(f"{directory}: cannot write the CA: {exc.strerror}") from None
    return info(cert, ca_cert)


def issue(directory: Path, name: str, role: str, sans: list[str] | None = None,
          days: int = 365, force: bool = False, now: dt.datetime | None = None) -> CertInfo:
    """``directory/NAME.pem`` and ``NAME.key`` (mode 600), signed by the CA in ``directory``.

    ``sans``: host names / IP addresses a peer may reach this member at (added to the name;
    default ``localhost`` and ``127.0.0.1``). ``now`` is for tests that need an expired one.
    """
    check_name(name)
    check_role(role)
    cert_path, key_path = directory / f"{name}.pem", directory / f"{name}.key"
    if not force and (cert_path.exists() or key_path.exists()):
        raise UserError(f"{cert_path} already exists: --force replaces it (a new key too)")
    ca_path = directory / CA_CERT
    if not ca_path.is_file():
        raise UserError(f"{directory}: no CA here ({CA_CERT}); make one with: "
                        f"companion pki init {directory}")
    ca = load_cert(ca_path, "CA certificate")
    ca_key = load_key(directory / CA_KEY, "the CA key")
    if not same_key(ca, ca_key):
        raise UserError(f"{directory / CA_KEY} is not the key of {ca_path}")
    now = now or utcnow()
    if (problem := info(ca, ca_path).problem(now)) is not None:
        raise UserError(f"{ca_path}: the CA {problem}")
    names: list[x509.GeneralName] = [x509.DNSName(name.lower())] if _HOST.match(name) else []
    for text in (sans if sans else DEFAULT_SANS):
        general = _san(text)
        if general not in names:
            names.append(general)
    key = ec.generate_private_key(ec.SECP256R1())
    # A certificate cannot outlive the CA that vouches for it.
    not_after = min(now + dt.timedelta(days=days), ca.not_valid_after_utc)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([
                x509.NameAttribute(NameOID.COMMON_NAME, name),
                x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
                x509.NameAttribute(NameOID.ORGANIZATION_NAME, ORGANIZATION)]))
            .issuer_name(ca.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - CLOCK_SKEW).not_valid_after(not_after)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(
                digital_signature=True, content_commitment=False, key_encipherment=False,
                data_encipherment=False, key_agreement=False, key_cert_sign=False,
                crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
            # Both: every member both listens (server) and connects (client) in Zenoh.
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                  ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .add_extension(x509.SubjectAlternativeName(names), critical=False)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256()))
    try:
        _write(key_path, _key_pem(key), 0o600)
        _write(cert_path, _cert_pem(cert), 0o644)
    except OSError as exc:
        raise UserError(f"{directory}: cannot write {name}'s certificate: {exc.strerror}") from None
    return info(cert, cert_path)
