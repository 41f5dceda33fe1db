"""A self-signed TLS certificate for `farm model --tls-self-signed`: WebXR needs a secure context on any host but
localhost, so a headset on the same network reaches the page over HTTPS.

In: a folder and the names the server is reached by. Out: certificate and key PEM files and the certificate's
SHA-256 fingerprint, which the headset's user compares with the one the browser shows before trusting it.
"""
from __future__ import annotations

import datetime
import ipaddress
import os
from pathlib import Path

from ..token_server import ServerError

__all__ = ["self_signed_certificate", "certificate_fingerprint"]

VALID_DAYS = 30


def certificate_fingerprint(pem: bytes) -> str:
    """SHA-256 of the certificate's DER bytes as colon-separated hex pairs (how browsers show it)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    digest = x509.load_pem_x509_certificate(pem).fingerprint(hashes.SHA256())
    return ":".join(f"{byte:02X}" for byte in digest)


def self_signed_certificate(folder: str | Path, names: list[str]) -> tuple[Path, Path, str]:
    """Write cert.pem and key.pem (the key readable by its owner only) for `names` (host names or addresses)
    into `folder`; returns (certificate path, key path, SHA-256 fingerprint)."""
    try:  # optional: only this flag needs it
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID
    except ImportError:
        raise ServerError("--tls-self-signed needs the `cryptography` package (pip install cryptography), or pass "
                          "--tls-cert and --tls-key") from None
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, names[0] if names else "treefarm model")])
    alternatives = []
    for name in dict.fromkeys([*names, "localhost", "127.0.0.1"]):
        try:
            alternatives.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            alternatives.append(x509.DNSName(name))
    now = datetime.datetime.now(datetime.timezone.utc)
    certificate = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject).public_key(key.public_key())
                   .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
                   .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
                   .add_extension(x509.SubjectAlternativeName(alternatives), critical=False)
                   .sign(key, hashes.SHA256()))
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    pem = certificate.public_bytes(serialization.Encoding.PEM)
    cert_path.write_bytes(pem)
    descriptor = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as handle:
        handle.write(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                       serialization.NoEncryption()))
    return cert_path, key_path, certificate_fingerprint(pem)
