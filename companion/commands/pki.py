"""``companion pki``: a fleet's private certificate authority, for Zenoh over mutual TLS.

  companion pki init DIR                         the CA: DIR/ca.pem, DIR/ca.key (mode 600)
  companion pki issue DIR NAME --role ROLE       DIR/NAME.pem + DIR/NAME.key (mode 600)
  companion pki show DIR/NAME                    subject, role, expiry, names, issuer

Roles: rover (NAME is its vehicle id: it may publish only under rover/NAME/** and answer only
rover/NAME/control), operator (may send control requests, and watch), monitor (may only
watch), router. Then pass ``--zenoh-tls DIR/NAME`` to run, demo, monitor, control and router.
Copy to each machine ca.pem, the .pem files, and only its own .key; the CA key stays home.
A router and a rover learn the others' roles from the certificates in DIR when their session
opens: restart them after issuing a new one. ``show`` exits 0 for a certificate valid now and
issued by the CA beside it, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import ExitCode, UserError
from ..security.roles import ROLES


def _days(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number of days: {text!r}") from None
    if not 1 <= value <= 36500:
        raise argparse.ArgumentTypeError(f"must be 1 to 36500 days, not {value}")
    return value


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "pki", help="certificates for a secured fleet (mutual TLS, roles)",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="pki_command", metavar="ACTION", required=True)
    i = sub.add_parser("init", help="make a private CA in DIR")
    i.add_argument("dir", metavar="DIR")
    i.add_argument("--days", type=_days, default=3650, help="CA validity (default 3650)")
    i.add_argument("--name", metavar="TEXT", help="the CA's common name")
    s = sub.add_parser("issue", help="issue DIR/NAME.pem and DIR/NAME.key")
    s.add_argument("dir", metavar="DIR")
    s.add_argument("name", metavar="NAME", help="a rover's vehicle id, or who holds it")
    s.add_argument("--role", required=True, choices=ROLES)
    s.add_argument("--san", action="append", default=[], metavar="HOST_OR_IP",
                   help="a host name or IP address peers dial this member at (repeatable; "
                        "default localhost and 127.0.0.1); NAME is always one")
    s.add_argument("--days", type=_days, default=365, help="validity (default 365)")
    s.add_argument("--force", action="store_true", help="replace an existing NAME (new key)")
    w = sub.add_parser("show", help="print a certificate's subject, role and expiry")
    w.add_argument("path", metavar="DIR/NAME")
    w.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..security import pki  # the cryptography library: only when a command needs it
    if args.pki_command == "init":
        ca = pki.init_ca(Path(args.dir), days=args.days, common_name=args.name)
        print(f"CA {ca.name!r} in {args.dir}: {ca.path} (give to every member), "
              f"{Path(args.dir) / pki.CA_KEY} (mode 600: keep it here); "
              f"valid until {pki.stamp(ca.not_after)}")
        return 0
    if args.pki_command == "issue":
        cert = pki.issue(Path(args.dir), args.name, args.role, args.san, args.days, args.force)
        print(f"{args.role} {cert.name!r}: {cert.path} and {cert.path.with_suffix('.key')} "
              f"(mode 600); names {', '.join(cert.sans)}; valid until "
              f"{pki.stamp(cert.not_after)}")
        return 0
    return show(args.path, args.json)


def show(spec: str, as_json: bool) -> int:
    from ..security import pki
    from ..security.identity import paths
    ca_path, cert_path, key_path = paths(spec)
    me = pki.info(pki.load_cert(cert_path), cert_path)
    problems = []
    if (problem := me.problem()) is not None:
        problems.append(problem)
    if not me.is_ca:
        if not ca_path.is_file():
            problems.append(f"no CA {ca_path} beside it to check it against")
        elif not _by_ca(cert_path, ca_path):
            problems.append(f"not issued by the CA in {ca_path}")
    days = (me.not_after - pki.utcnow()).total_seconds() / 86400
    view = {"path": str(cert_path), "subject": me.name, "role": "CA" if me.is_ca else me.role,
            "issuer": me.issuer, "not_before": pki.stamp(me.not_before),
            "not_after": pki.stamp(me.not_after), "days_left": round(days, 1),
            "names": list(me.sans), "sha256": me.fingerprint,
            "key": str(key_path) if key_path.exists() and not me.is_ca else None,
            "valid": not problems, "problems": problems}
    if as_json:
        print(json.dumps(view))
    else:
        left = f"{days:.0f} days left" if days >= 0 else "EXPIRED"
        lines = [f"subject   {me.name}", f"role      {view['role'] or '(none)'}",
                 f"issuer    {me.issuer}",
                 f"valid     {view['not_before']} to {view['not_after']} ({left})",
                 f"names     {', '.join(me.sans) or '-'}", f"sha256    {me.fingerprint}",
                 "status    " + ("ok" if not problems else "; ".join(problems))]
        print("\n".join(lines))
    return ExitCode.OK if not problems else ExitCode.CHECK_FAILED


def _by_ca(cert_path: Path, ca_path: Path) -> bool:
    from ..security import pki
    try:
        return pki.issued_by(pki.load_cert(cert_path), pki.load_cert(ca_path, "CA certificate"))
    except UserError:
        return False
