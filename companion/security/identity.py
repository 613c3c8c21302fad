"""One process's fleet identity, checked before any session opens: who am I, what role, who else.

``--zenoh-tls DIR/NAME`` names ``DIR/ca.pem`` (the fleet's CA), ``DIR/NAME.pem`` and
``DIR/NAME.key``. Everything Zenoh would otherwise report late and vaguely (a handshake that
fails with "unable to connect") is checked here first and said in one line: a missing or
unreadable file, a key that others can read or that is not the certificate's, a certificate
from another CA, expired or not yet valid, or of the wrong role for the command.

The roster is every valid certificate the CA issued in the same directory: Zenoh's access
control matches peers by their certificate's common name and has no notion of a role, so the
rules list the names per role (see :mod:`.acl`). Issue a certificate, restart the sessions whose
rules should know it (Zenoh reads its access control only when a session opens).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

from cryptography import x509

from ..errors import UserError
from . import pki
from .roles import POSSESSIVE

FLAG = "--zenoh-tls"


@dataclass(frozen=True)
class Identity:
    """A member's checked certificate: Zenoh reads the files, access control uses the rest."""

    name: str
    role: str
    ca: Path                    # absolute: Zenoh opens these files itself
    cert: Path
    key: Path
    not_after: dt.datetime
    roster: dict[str, tuple[str, ...]] = field(default_factory=dict)   # role -> names

    def describe(self) -> str:
        others = ", ".join(f"{len(self.roster.get(r, ()))} {r}(s)" for r in pki.ROLES)
        return (f"mutual TLS as {self.role} {self.name!r} (CA {self.ca}, certificate valid until "
                f"{pki.stamp(self.not_after)}); access control knows {others}")


def paths(spec: str) -> tuple[Path, Path, Path]:
    """``DIR/NAME`` (``NAME.pem`` / ``NAME.key`` accepted too) -> CA, certificate, key."""
    path = Path(spec).expanduser()
    if path.suffix in (".pem", ".key"):
        path = path.with_suffix("")
    return path.parent / pki.CA_CERT, path.with_suffix(".pem"), path.with_suffix(".key")


def from_spec(spec: str, roles: tuple[str, ...] = (), now: dt.datetime | None = None) -> Identity:
    ca, cert, key = paths(spec)
    if not spec.strip() or cert.stem == "ca":
        raise UserError(f"{FLAG} {spec!r}: name a member's certificate, DIR/NAME "
                        "(DIR/NAME.pem and DIR/NAME.key, with DIR/ca.pem beside them)")
    return load(ca, cert, key, roles, f"{FLAG} {spec}", now)


def load(ca: Path, cert: Path, key: Path, roles: tuple[str, ...] = (), where: str = FLAG,
         now: dt.datetime | None = None, key_flag: str = FLAG) -> Identity:
    """Check the three files and the certificate's role; ``where`` prefixes every message
    (``key_flag`` the key file's, which names the file itself)."""
    now = now or pki.utcnow()

    def fail(text: str) -> UserError:
        return UserError(f"{where}: {text}")

    if not ca.is_file():
        raise fail(f"no CA certificate {ca} (companion pki init {ca.parent} makes one)")
    if not cert.is_file():
        raise fail(f"no certificate {cert} (companion pki issue {cert.parent} {cert.stem} "
                   f"--role ROLE makes one)")
    try:
        ca_cert = pki.load_cert(ca, "CA certificate")
        my_cert = pki.load_cert(cert)
    except UserError as err:
        raise fail(str(err)) from None
    my_key = pki.load_key(key, key_flag)
    ca_info, me = pki.info(ca_cert, ca), pki.info(my_cert, cert)
    if not pki.same_key(my_cert, my_key):
        raise fail(f"{key} is not the key of {cert}")
    if not pki.issued_by(my_cert, ca_cert):
        raise fail(f"{cert} was not issued by the CA in {ca} (a certificate from another CA)")
    if (problem := ca_info.problem(now)) is not None:
        raise fail(f"the CA {ca} {problem}")
    if (problem := me.problem(now)) is not None:
        hint = (f"renew it: companion pki issue {cert.parent} {me.name} --role "
                f"{me.role or 'ROLE'} --force" if now > me.not_after
                else "is this machine's clock right?")
        raise fail(f"{cert} {problem} ({hint})")
    if me.role is None:
        raise fail(f"{cert} names no role (issue it with companion pki issue ... --role ROLE)")
    if roles and me.role not in roles:
        wanted = " or ".join(POSSESSIVE[r] for r in roles)
        raise fail(f"{cert} is {POSSESSIVE[me.role]} certificate ({me.name}); this command "
                   f"needs {wanted}")
    return Identity(name=me.name, role=me.role, ca=ca.resolve(), cert=cert.resolve(),
                    key=key.resolve(), not_after=me.not_after,
                    roster=roster(ca.parent, ca_cert, now, me))


def roster(directory: Path, ca_cert: x509.Certificate, now: dt.datetime,
           me: pki.CertInfo) -> dict[str, tuple[str, ...]]:
    """Role -> names of every certificate in ``directory`` that this CA issued and that is
    valid now. Anything else there (another CA's, expired, unreadable) is left out: a peer
    holding it could not complete the TLS handshake anyway."""
    seen: dict[str, set[str]] = {role: set() for role in pki.ROLES}
    if me.role is not None:   # (load refuses a certificate without one)
        seen[me.role].add(me.name)
    for path in sorted(directory.glob("*.pem")):
        if path.name == pki.CA_CERT:
            continue
        try:
            cert = pki.load_cert(path)
        except UserError:
            continue
        other = pki.info(cert, path)
        if (other.role is None or other.problem(now) is not None
                or not pki.issued_by(cert, ca_cert)):
            continue
        try:
            pki.check_name(other.name)
        except UserError:
            continue
        seen[other.role].add(other.name)
    return {role: tuple(sorted(names)) for role, names in seen.items()}
