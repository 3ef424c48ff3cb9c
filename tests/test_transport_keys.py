"""interfaces/keys.py: one prefix per run, valid Zenoh key expressions, wildcard coverage."""
import pytest
import zenoh

from interfaces import codec, keys as K


def test_keys_of_a_vehicle_name_and_of_an_explicit_prefix():
    k = K.keys("v1")
    assert k.prefix == "ellipsled/v1"
    assert (k.sensors, k.jets, k.faults) == ("ellipsled/v1/sim/sensors", "ellipsled/v1/fsw/jets",
                                             "ellipsled/v1/sim/faults")
    assert (k.truth, k.state, k.events) == ("ellipsled/v1/sim/truth", "ellipsled/v1/fsw/state",
                                            "ellipsled/v1/fsw/events")
    assert [k.alive_sim, k.alive_fsw, k.alive_bridge, k.alive_console] == \
        [f"ellipsled/v1/alive/{r}" for r in ("sim", "fsw", "bridge", "console")]
    assert K.keys("ellipsled/run-42.b").sensors == "ellipsled/run-42.b/sim/sensors"
    assert K.keys("/v1/") == k
    with pytest.raises(ValueError):
        k.alive("ground")


@pytest.mark.parametrize("bad", ["", "a/*", "a/**", "a//b", "v 1", "v$1", "a/#b", 7])
def test_bad_prefixes_are_refused(bad):
    with pytest.raises(ValueError):
        K.keys(bad)


def test_every_key_is_a_canonical_zenoh_key_and_the_wildcard_covers_the_tokens():
    k = K.keys("v1")
    topics = [k.sensors, k.jets, k.faults, k.fault_log, k.truth, k.state, k.events]
    for key in topics + [k.alive(r) for r in K.ROLES]:
        assert str(zenoh.KeyExpr(key)) == key
    anyk = zenoh.KeyExpr(k.alive_any)
    assert all(anyk.includes(zenoh.KeyExpr(k.alive(r))) for r in K.ROLES)
    assert not anyk.intersects(zenoh.KeyExpr(k.sensors))
    # another vehicle's topics never match this one's
    assert not zenoh.KeyExpr(K.keys("v2").sensors).intersects(zenoh.KeyExpr(k.sensors))
    # every registered schema's topic is one of these keys
    assert {k.topic(s.key_suffix) for s in codec.REGISTRY.values()} <= set(topics)
