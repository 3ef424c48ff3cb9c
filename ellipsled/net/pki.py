"""``ellipsled pki init DIR``: a certificate authority and one certificate per SIL role,
for Zenoh's TLS with mutual authentication (data/zenoh/*.json5), and one for the Dask
cluster of the Monte Carlo campaigns (``ellipsled montecarlo --tls-*``).

The router identifies each peer by its certificate's common name, which is the role
name its access-control policy (data/zenoh/router.json5) grants rights to: ``sim``
publishes the plant's keys, ``fsw`` the flight software's, ``viz`` only subscribes. The
router's certificate also names the hosts/addresses clients reach it at (TLS checks the
name: ``--router-host``).

Private keys are written 0600 in a 0700 folder, never inside the source repository
(a key committed by mistake is a key published), and an existing CA is never
overwritten: give another folder, or delete the old one on purpose.
"""
from __future__ import annotations

import datetime as dt
import ipaddress
import os
import sys
from pathlib import Path

from common import argtypes

# Role -> certificate common name; the names the router's policy refers to. ``dask``:
# the Monte Carlo cluster's scheduler, workers and client (Dask's TLS is mutual too; each
# end is a server and a client).
ROLES = ("router", "sim", "fsw", "viz", "dask")
SERVER_ROLES = ("router", "dask")
CA_NAME = "ellipsled CA"
DEFAULT_ROUTER_HOSTS = ("localhost", "127.0.0.1")
DEFAULT_DAYS = 365
REPO_ROOT = Path(__file__).resolve().parents[2]


def cert_path(d: Path, role: str) -> Path:
    return Path(d) / f"{role}.pem"


def key_path(d: Path, role: str) -> Path:
    return Path(d) / f"{role}.key"


def inside_repository(path: Path) -> Path | None:
    """The git work tree ``path`` lies in (this project's or any other), or None."""
    p = Path(path).resolve()
    for d in (p, *p.parents):
        if (d / ".git").exists():
            return d
    if p == REPO_ROOT or REPO_ROOT in p.parents:
        return REPO_ROOT
    return None


def _key():
    from cryptography.hazmat.primitives.asymmetric import ec
    return ec.generate_private_key(ec.SECP256R1())


def _name(cn: str):
    from cryptography.x509.oid import NameOID
    from cryptography import x509
    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "ellipsled"),
                      x509.NameAttribute(NameOID.COMMON_NAME, cn)])


def _san(hosts) -> list:
    from cryptography import x509
    out = []
    for h in hosts:
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            out.append(x509.DNSName(h))
    return out


def _write_private(path: Path, data: bytes) -> None:
    """Create ``path`` 0600 from the start (never world-readable, even for an instant)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)


def _pem_key(k) -> bytes:
    from cryptography.hazmat.primitives import serialization
    return k.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                           serialization.NoEncryption())


def _pem_cert(c) -> bytes:
    from cryptography.hazmat.primitives import serialization
    return c.public_bytes(serialization.Encoding.PEM)


def init(d: str | Path, router_hosts=DEFAULT_ROUTER_HOSTS, days: int = DEFAULT_DAYS,
         ca_name: str = CA_NAME) -> dict[str, Path]:
    """Write ``ca.pem`` (+ ``ca.key``) and ``<role>.pem`` / ``<role>.key`` for every role
    into ``d``; returns {name: path}. Raises ValueError (inside a repository, a CA already
    there, bad hosts or days)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    d = Path(d)
    repo = inside_repository(d)
    if repo is not None:
        raise ValueError(f"{d}: inside the repository {repo}; private keys are kept outside any "
                         "source tree (e.g. /etc/ellipsled/pki or ~/.ellipsled/pki)")
    if not (isinstance(days, int) and 1 <= days <= 3650):
        raise ValueError(f"days must be an integer in 1..3650, got {days!r}")
    hosts = [str(h).strip() for h in router_hosts if str(h).strip()]
    if not hosts:
        raise ValueError("at least one router host name or address is needed (--router-host)")
    if (d / "ca.key").exists() or (d / "ca.pem").exists():
        raise ValueError(f"{d}: a CA is already there; choose another folder or remove it on purpose")
    d.mkdir(parents=True, exist_ok=True)
    os.chmod(d, 0o700)

    now = dt.datetime.now(dt.timezone.utc) - dt.timedelta(minutes=5)    # tolerate small clock skew
    until = now + dt.timedelta(days=days)
    ca_key = _key()
    ca = (x509.CertificateBuilder().subject_name(_name(ca_name)).issuer_name(_name(ca_name))
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now).not_valid_after(until)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False,
                                       data_encipherment=False, key_agreement=False, key_cert_sign=True,
                                       crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
          .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
          .sign(ca_key, hashes.SHA256()))
    out = {"ca": d / "ca.pem", "ca_key": d / "ca.key"}
    _write_private(out["ca_key"], _pem_key(ca_key))
    out["ca"].write_bytes(_pem_cert(ca))

    for role in ROLES:
        k = _key()
        # every certificate may act as a TLS client; the router's also as a server, under
        # the names clients reach it at. A client certificate carries its role as a DNS
        # name too (rustls requires a subject alternative name in end-entity certificates).
        usages = [ExtendedKeyUsageOID.CLIENT_AUTH] + ([ExtendedKeyUsageOID.SERVER_AUTH] if role in SERVER_ROLES else [])
        b = (x509.CertificateBuilder().subject_name(_name(role)).issuer_name(ca.subject)
             .public_key(k.public_key()).serial_number(x509.random_serial_number())
             .not_valid_before(now).not_valid_after(until)
             .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
             .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
             .add_extension(x509.SubjectAlternativeName(_san(hosts if role == "router" else [role])), critical=False)
             .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False))
        cert = b.sign(ca_key, hashes.SHA256())
        out[f"{role}_key"] = key_path(d, role)
        out[role] = cert_path(d, role)
        _write_private(out[f"{role}_key"], _pem_key(k))
        out[role].write_bytes(_pem_cert(cert))
    return out


def add_pki_parser(sub) -> None:
    p = sub.add_parser("pki", help="certificates for Zenoh's mutual TLS (a CA and one per role)")
    psub = p.add_subparsers(dest="pki_cmd", required=True)
    q = psub.add_parser("init", help="write a CA and the router/sim/fsw/viz/dask certificates into DIR",
                        description=__doc__)
    q.add_argument("dir", help="folder for the certificates and keys (outside any repository)")
    q.add_argument("--router-host", action="append", default=None, metavar="NAME_OR_ADDRESS",
                   help="a name or address clients use to reach the router (repeatable; default "
                        + ", ".join(DEFAULT_ROUTER_HOSTS) + ")")
    q.add_argument("--days", type=argtypes.int_range(1, 36500), default=DEFAULT_DAYS, help="validity of every certificate")

    def run(a):
        try:
            paths = init(a.dir, a.router_host or DEFAULT_ROUTER_HOSTS, a.days)
        except (ValueError, OSError) as e:
            print(f"ellipsled pki: {e}", file=sys.stderr)
            return 2
        print(f"wrote a CA and certificates for {', '.join(ROLES)} into {Path(a.dir).resolve()} "
              f"(keys 0600; router names: {', '.join(a.router_host or DEFAULT_ROUTER_HOSTS)})")
        for name, path in paths.items():
            print(f"  {name:10s} {path}")
        return 0
    q.set_defaults(func=run)
