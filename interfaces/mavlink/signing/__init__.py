"""MAVLink 2 signing for the ground link, verify-first, used by both ends (the vehicle and
the ground station): ``keys`` (key files), ``sign`` (Signer), ``verify`` (SigningVerifier),
``link`` (SignedLink). Policy, and why not pymavlink's own check: interfaces/mavlink/README.md."""
from .keys import main

__all__ = ["main"]
