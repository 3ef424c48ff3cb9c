"""What the ground station believes: with the key, only frames of the vehicle whose
signature verified, and only from the vehicle it first verified (an unsigned HEARTBEAT
cannot show the vehicle ARMED or in another mode, nor keep the link age fresh; a second
sender of system 1 cannot take the link over); text from the link is kept with its
control characters escaped. Frames are built with the MAVLink signing rules (Signer) and
pymavlink's own packer, and fed to a client without a socket."""
from __future__ import annotations

import time

from gse.client import GroundClient
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.keys import SigningKey
from interfaces.mavlink.signing.sign import Signer
from interfaces.vocabulary import DEFAULT_VEHICLE, parse_udp

VEHICLE_A, VEHICLE_B = parse_udp(DEFAULT_VEHICLE, "vehicle"), ("127.0.0.1", 40000)


def heartbeat(armed: bool):
    return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_GENERIC,
                                         mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0, 3, mav.MAV_STATE_ACTIVE, 3)


def test_with_the_key_an_unsigned_vehicle_heartbeat_is_not_believed():
    key = SigningKey.generate()
    client = GroundClient(key, listen=None)
    unsigned = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    assert client.feed(heartbeat(True).pack(unsigned), VEHICLE_A, time.time()) == 0
    assert "HEARTBEAT" not in client.state.latest and client.link_age_s() is None
    assert client.stats["rx_unsigned"] == 1
    vehicle = Signer(key, system_id=1, component_id=1)
    assert client.feed(vehicle.pack(heartbeat(False)), VEHICLE_A, time.time()) == 1
    assert client.state.latest["HEARTBEAT"].base_mode == 0


def test_the_first_verified_vehicle_is_pinned():
    key = SigningKey.generate()
    client = GroundClient(key, listen=None)
    a = Signer(key, system_id=1, component_id=1)
    b = Signer(key, system_id=1, component_id=1, link_id=9)   # another sender of system 1, key holder
    assert client.feed(a.pack(heartbeat(False)), VEHICLE_A, time.time()) == 1
    assert client.feed(b.pack(heartbeat(True)), VEHICLE_B, time.time()) == 0
    assert client.vehicle_addr == VEHICLE_A and client.vehicle_source == VEHICLE_A
    assert client.state.latest["HEARTBEAT"].base_mode == 0 and client.stats["rx_foreign"] == 1


def test_text_from_the_link_is_kept_with_control_characters_escaped():
    key = SigningKey.generate()
    client = GroundClient(key, listen=None)
    vehicle = Signer(key, system_id=1, component_id=1)
    client.feed(vehicle.pack(mav.MAVLink_statustext_message(4, b"\x1b]0;owned\x07\x1b[2J done")), VEHICLE_A,
                time.time())
    text = client.state.events[-1].text
    assert text == "\\x1b]0;owned\\x07\\x1b[2J done" and text.isprintable()
