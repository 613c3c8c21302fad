"""Zenoh's mutual-TLS settings for an identity, and the rule that nothing goes in clear.

The settings are Zenoh's own (``transport/link/tls`` in its JSON5 config): Zenoh does the TLS
(rustls). Both directions are mutual: a listener asks every peer for a certificate from the CA
(``enable_mtls``), a connecting side presents its own and checks that the listener's
certificate names the host it dialled (``verify_name_on_connect``, against the subject
alternative names). Links close when the remote certificate expires.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import UserError

if TYPE_CHECKING:        # identity loads the cryptography library: not for a plain session
    from .identity import Identity

SCHEME = "tls/"
TLS_KEY = "transport/link/tls"


def settings(identity: Identity) -> dict[str, Any]:
    """The value of ``transport/link/tls``: one certificate for both listening and connecting."""
    return {
        "root_ca_certificate": str(identity.ca),
        "listen_certificate": str(identity.cert),
        "listen_private_key": str(identity.key),
        "connect_certificate": str(identity.cert),
        "connect_private_key": str(identity.key),
        "enable_mtls": True,
        "verify_name_on_connect": True,
        "close_link_on_expiration": True,
    }


def endpoints_for(value: Any, mode: str) -> list[str]:
    """Zenoh's ``listen/endpoints`` / ``connect/endpoints`` value (a list, or one list per
    mode) as the list that applies to ``mode``."""
    if isinstance(value, dict):
        value = value.get(mode) or []
    return [str(e) for e in value or []]


def check_endpoints(endpoints: list[str], what: str) -> None:
    """Refuse any endpoint that is not TLS: one clear link would carry the secret in clear."""
    for ep in endpoints:
        if not ep.startswith(SCHEME):
            raise UserError(f"{what} {ep}: with mutual TLS every endpoint must be "
                            f"tls/HOST:PORT (nothing goes in clear)")
