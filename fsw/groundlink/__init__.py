"""The FSW's MAVLink 2 ground link; the interface it implements (messages, rates,
commands, parameters, security) is documented in interfaces/mavlink/README.md.

- ``link.py``: the protocol: UDP socket, verify-first signing, receive and dispatch,
  telemetry scheduling and sending (``GroundLink``, what the executive ticks).
- ``senders.py``: what the link keeps per address: telemetry peers, unsigned read budgets.
- ``streams.py``: the telemetry streams (names, default rates) and what each says now.
- ``telemetry.py``: each telemetry message built from the FlightSoftware's state.
- ``commands.py``: translation of COMMAND_LONG to the FlightSoftware command API and of
  the parameter protocol to its parameter registry.
- ``events.py``: the MAVLink events interface (EVENT, CURRENT_EVENT_SEQUENCE, REQUEST_EVENT);
  its ``GroundLink`` is link.GroundLink with that interface, the one this package exports.
"""
from .events import GroundLink
from .link import DEFAULT_BIND, DEFAULT_GCS
from .streams import DEFAULT_RATES_HZ
from .telemetry import euler321

__all__ = ["GroundLink", "DEFAULT_RATES_HZ", "DEFAULT_GCS", "DEFAULT_BIND", "euler321"]
