"""`ellipsled pki init` and `ellipsled router` on loopback, with the shipped configurations
(data/zenoh/*.json5): mutual TLS refuses a peer without a certificate of the CA, and the
access-control policy lets each role publish only its own keys."""
from __future__ import annotations

import json
import os
import stat
import subprocess
import time
from pathlib import Path

import pytest
import zenoh

from ellipsled.net import pki
from ellipsled.procs import ELLIPSLED, stop_process
from interfaces import transport
from interfaces.keys import keys


pytestmark = pytest.mark.slow

ZCONF = Path(__file__).resolve().parent.parent / "data" / "zenoh"
K = keys("ellipsled/acltest")


def test_pki_init_writes_a_ca_and_one_certificate_per_role_with_private_keys(tmp_path):
    from cryptography import x509
    d = tmp_path / "pki"
    paths = pki.init(d, ["localhost", "127.0.0.1", "10.0.0.1"])
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    for role in pki.ROLES:
        assert stat.S_IMODE(paths[f"{role}_key"].stat().st_mode) == 0o600, role
        c = x509.load_pem_x509_certificate(paths[role].read_bytes())
        assert c.subject.get_attributes_for_oid(x509.oid.NameOID.COMMON_NAME)[0].value == role
        c.verify_directly_issued_by(ca)                   # raises if not signed by this CA
    san = x509.load_pem_x509_certificate(paths["router"].read_bytes()).extensions \
        .get_extension_for_class(x509.SubjectAlternativeName).value
    assert "localhost" in san.get_values_for_type(x509.DNSName)
    assert [str(a) for a in san.get_values_for_type(x509.IPAddress)] == ["127.0.0.1", "10.0.0.1"]
    assert stat.S_IMODE((d / "ca.key").stat().st_mode) == 0o600
    with pytest.raises(ValueError, match="already there"):
        pki.init(d)                                        # never overwrites a CA


def test_pki_init_refuses_to_write_inside_the_repository(tmp_path):
    repo = Path(pki.__file__).resolve().parents[2]
    r = subprocess.run(ELLIPSLED + ["pki", "init", str(repo / "pki-test")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "inside the repository" in r.stderr, r.stderr
    assert not (repo / "pki-test").exists()
    (tmp_path / "other" / ".git").mkdir(parents=True)          # any git work tree
    with pytest.raises(ValueError, match="inside the repository"):
        pki.init(tmp_path / "other" / "keys")


def test_router_refuses_a_configuration_not_in_router_mode(tmp_path):
    r = subprocess.run(ELLIPSLED + ["router", "--config", str(ZCONF / "sim.json5")], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "needs mode" in r.stderr, r.stderr


# -------------------------------------------------------------------- a router on loopback

def client_config(role: str, endpoint: str, pki_dir: Path, *, cert_role: str | None = None,
                  ca: Path | None = None, timeout_ms: int = 3000) -> zenoh.Config:
    """The shipped client configuration of ``role`` pointed at ``endpoint``, with absolute
    certificate paths (``cert_role=""``: no client certificate at all)."""
    c = zenoh.Config.from_file(str(ZCONF / f"{role}.json5"))
    c.insert_json5("connect/endpoints", json.dumps([endpoint]))
    c.insert_json5("connect/timeout_ms", str(timeout_ms))
    c.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca or pki_dir / "ca.pem")))
    who = role if cert_role is None else cert_role
    if who:
        c.insert_json5("transport/link/tls/connect_certificate", json.dumps(str(pki_dir / f"{who}.pem")))
        c.insert_json5("transport/link/tls/connect_private_key", json.dumps(str(pki_dir / f"{who}.key")))
    else:
        c.insert_json5("transport/link/tls/connect_certificate", "null")
        c.insert_json5("transport/link/tls/connect_private_key", "null")
    return c


@pytest.fixture(scope="module")
def router(tmp_path_factory):
    """`ellipsled router` with the shipped configuration, run from a folder holding pki/."""
    d = tmp_path_factory.mktemp("router")
    pki.init(d / "pki")
    endpoint = f"tls/localhost:{transport.free_port()}"
    log = open(d / "router.log", "w")
    p = subprocess.Popen(ELLIPSLED + ["router", "--config", str(ZCONF / "router.json5"), "--listen", endpoint],
                         cwd=d, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while "listening on" not in (d / "router.log").read_text():
            assert p.poll() is None and time.monotonic() < deadline, (d / "router.log").read_text()
            time.sleep(0.05)
        yield endpoint, d / "pki", d
    finally:
        stop_process(p, 10)
        log.close()
    assert p.returncode == 0, (d / "router.log").read_text()


def _drain(sub) -> list[bytes]:
    out = []
    while (s := sub.try_recv()) is not None:
        out.append(s.payload.to_bytes())
    return out


def test_each_role_publishes_only_its_own_keys_through_the_router(router):
    endpoint, d, _ = router
    sim = zenoh.open(client_config("sim", endpoint, d))
    fsw = zenoh.open(client_config("fsw", endpoint, d))
    viz = zenoh.open(client_config("viz", endpoint, d))
    ents = []
    try:
        sub_sensors = fsw.declare_subscriber(K.sensors, zenoh.handlers.FifoChannel(64))
        sub_jets = sim.declare_subscriber(K.jets, zenoh.handlers.FifoChannel(64))
        sub_faults = sim.declare_subscriber(K.faults, zenoh.handlers.FifoChannel(64))
        sub_truth = viz.declare_subscriber(K.truth, zenoh.handlers.FifoChannel(64))
        sub_state = viz.declare_subscriber(K.state, zenoh.handlers.FifoChannel(64))
        ents += [sub_sensors, sub_jets, sub_faults, sub_truth, sub_state]
        pubs = {(who, key): s.declare_publisher(key) for who, s, key in (
            ("sim", sim, K.sensors), ("sim", sim, K.truth), ("fsw", fsw, K.jets), ("fsw", fsw, K.state),
            ("fsw", fsw, K.faults), ("viz", viz, K.jets), ("viz", viz, K.faults), ("viz", viz, K.sensors), ("sim", sim, K.state))}
        ents += list(pubs.values())
        genuine = [("sim", K.sensors), ("fsw", K.jets), ("fsw", K.faults), ("sim", K.truth), ("fsw", K.state)]
        for g in genuine:                   # a sample put before its subscriber is matched is lost
            assert transport.wait_for_subscriber(pubs[g], 5), g
        # the router does not even tell the viewer that the plant subscribes to the jets
        assert not pubs[("viz", K.jets)].matching_status.matching
        for (who, key), p in pubs.items():  # the forgeries first, then the genuine samples
            if (who, key) not in genuine:
                p.put(f"{who}:{key}".encode())
        for who, key in genuine:
            pubs[(who, key)].put(f"{who}:{key}".encode())
        subs = {K.sensors: sub_sensors, K.jets: sub_jets, K.faults: sub_faults, K.truth: sub_truth,
                K.state: sub_state}
        got = {key: [] for key in subs}
        deadline = time.monotonic() + 10.0  # sanity: the genuine ones arrive within milliseconds
        while time.monotonic() < deadline:
            for key, sub in subs.items():
                got[key] += _drain(sub)
            if all(got.values()):
                break
            time.sleep(0.01)
        # (a session's own publications reach its own subscribers without the router: the
        # forgeries below come from other sessions)
        assert got[K.sensors] == [f"sim:{K.sensors}".encode()]      # not the viewer's forgery
        assert got[K.jets] == [f"fsw:{K.jets}".encode()]            # the viewer's never arrives
        assert got[K.faults] == [f"fsw:{K.faults}".encode()]        # injections only via the FSW
        assert got[K.truth] == [f"sim:{K.truth}".encode()]
        assert got[K.state] == [f"fsw:{K.state}".encode()]          # not the plant's forgery
        # presence: every role sees the others' liveliness tokens
        tok = transport.declare_alive(sim, K, "sim")
        ents.append(tok)
        assert transport.wait_for_alive(fsw, K.alive_sim, 5)
        assert transport.wait_for_alive(viz, K.alive_sim, 5)
    finally:
        transport.close(*ents, sim, fsw, viz)


def test_a_peer_without_a_certificate_cannot_connect(router):
    endpoint, d, _ = router
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        zenoh.open(client_config("sim", endpoint, d, cert_role="", timeout_ms=1500))


def test_a_certificate_of_another_ca_is_refused(router, tmp_path):
    endpoint, d, _ = router
    rogue = tmp_path / "rogue"
    pki.init(rogue)                       # same role names, another CA
    c = client_config("sim", endpoint, rogue, ca=d / "ca.pem", timeout_ms=1500)   # trusts the real router
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        zenoh.open(c)
    # the same client with the genuine certificate connects (the refusal is the certificate's)
    s = zenoh.open(client_config("sim", endpoint, d, timeout_ms=1500))
    try:
        assert s.info.routers_zid()
    finally:
        s.close()


def test_the_router_drops_a_viewer_put_even_when_the_viewer_knows_the_plant_subscribes(router, tmp_path):
    """With the shipped policy a viewer's client is not even told that the plant subscribes
    to the jets, so it may never send. Here the viewer is also allowed to learn of
    subscribers: its put is then sent for sure (its publisher matches), and the router's
    ingress rule is what stops it."""
    _, d, _ = router
    conf = zenoh.Config.from_file(str(ZCONF / "router.json5"))
    endpoint = f"tls/localhost:{transport.free_port()}"
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    for key, name in (("root_ca_certificate", "ca.pem"), ("listen_certificate", "router.pem"),
                      ("listen_private_key", "router.key")):
        conf.insert_json5(f"transport/link/tls/{key}", json.dumps(str(d / name)))
    policies = json.loads(conf.get_json("access_control/policies"))
    viewer = next(p for p in policies if p["id"] == "viewer")
    viewer["rules"].append("matching")
    conf.insert_json5("access_control/policies", json.dumps(policies))
    rtr = zenoh.open(conf)
    sim = zenoh.open(client_config("sim", endpoint, d))
    viz = zenoh.open(client_config("viz", endpoint, d))
    sub = pub = None
    try:
        sub = sim.declare_subscriber(K.jets, zenoh.handlers.FifoChannel(64))
        pub = viz.declare_publisher(K.jets)
        assert transport.wait_for_subscriber(pub, 10), "the viewer should now see the plant's subscription"
        for i in range(10):
            pub.put(b"forged")
        time.sleep(0.5)
        assert _drain(sub) == []
    finally:
        transport.close(sub, pub, sim, viz, rtr)


def _tokens_seen(session, prefix: str, own_key: str) -> set[str]:
    """Token keys under ``prefix`` that ``session`` is told of (declared and live), up to and
    including ``own_key`` (declared last by the forger: anything the router let through
    came before it), and what a liveliness query then answers."""
    patterns = (f"{prefix}/alive/*", f"{prefix}/alive/*/ready")     # what the policy lets a role ask
    subs = [session.liveliness().declare_subscriber(k, zenoh.handlers.FifoChannel(64), history=True)
            for k in patterns]
    seen: set[str] = set()
    try:
        deadline = time.monotonic() + 10
        while own_key not in seen:
            assert time.monotonic() < deadline, f"{own_key} never seen; seen {seen}"
            got = [s for s in (sub.try_recv() for sub in subs) if s is not None]
            if not got:
                time.sleep(0.01)
            seen.update(str(s.key_expr) for s in got if s.kind == zenoh.SampleKind.PUT)
    finally:
        for sub in subs:
            sub.undeclare()
    for k in patterns:
        for r in session.liveliness().get(k, timeout=5.0):
            if r.ok is not None:
                seen.add(str(r.ok.key_expr))
    return seen


@pytest.mark.parametrize("forger,own,forged", [
    ("viz", "bridge", ("fsw", "sim", "fsw/ready")),
    ("sim", "sim", ("fsw", "fsw/ready", "bridge")),
    ("fsw", "fsw", ("sim", "bridge")),
])
def test_each_certificate_declares_only_its_own_liveliness_tokens(router, forger, own, forged):
    """A plant that starts its clock on a forged ``alive/fsw/ready``, or an FSW that flies for
    a forged plant, would be misled by any certificate: the router lets each role declare
    only its own presence, and still tells every role of every genuine token."""
    endpoint, d, _ = router
    prefix = f"ellipsled/presence-{forger}"
    watcher_role = "fsw" if forger != "fsw" else "sim"
    bad = zenoh.open(client_config(forger, endpoint, d))
    watcher = zenoh.open(client_config(watcher_role, endpoint, d))
    tokens = []
    try:
        for role in forged:
            tokens.append(bad.liveliness().declare_token(f"{prefix}/alive/{role}"))
        own_key = f"{prefix}/alive/{own}"
        tokens.append(bad.liveliness().declare_token(own_key))
        seen = _tokens_seen(watcher, prefix, own_key)
        assert seen == {own_key}, f"forged presence got through: {seen - {own_key}}"
    finally:
        transport.close(*tokens, bad, watcher)
