"""The MAVLink 2 ground link: the ellipsled dialect and verify-first signing.

    from interfaces.mavlink import dialect as mav      # generated pymavlink bindings
    from interfaces.mavlink.signing.keys import SigningKey
    from interfaces.mavlink.signing.link import SignedLink

- ``ellipsled.xml``: the dialect (includes common.xml); the one definition.
- ``generated/ellipsled.py``: bindings generated from it by pymavlink's mavgen
  (``python -m interfaces.mavlink.generate``; a test checks they are up to date).
- ``framing.py``: frame layout and a robust datagram / stream splitter.
- ``signing/``: key files (``keys.py``), the signer (``sign.py``), the verifier that checks
  every frame before pymavlink decodes it (``verify.py``; pymavlink 2.4.50's own check has
  a lockout weakness), and both ends over one key (``link.py``).
"""
from .generated import ellipsled as dialect

__all__ = ["dialect"]
