"""Fleet security: a private CA (pki), a process's checked identity, Zenoh mutual TLS (tls) and role access control (acl).

May import: ``errors``, ``secretfile``, the cryptography library; never zenoh (``bus`` hands Zenoh these settings).
"""
