"""Real Zenoh sessions on loopback (127.0.0.1, multicast scouting off), no mocks.

1. peer.json5: a STATE message published by the "HAL" arrives bit-exact at the
   "policy"; a COMMAND goes back through SafetyController.receive; liveliness works.
2. secure.json5 / secure_client.json5: TLS + user/password + access control. A client
   without credentials (or with a wrong password, or not trusting the CA) never
   connects; an authenticated "monitor" sees the HAL's cmd subscriber but its put on
   the cmd key is dropped by the ACL, while its E-stop arrives; "policy" may command.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import shutil
import subprocess
import threading
import time
from typing import Callable

import numpy as np
import pytest
import zenoh

from virl_quad import robots
from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, RobotState
from virl_quad.deploy.safety import SafetyController
from virl_quad.deploy.zenoh_config import config_path, free_port, load_config, publisher_options

ROBOT_ID = "pupper-test"


def wait_until(pred: Callable[[], bool], timeout: float = 5.0) -> bool:
    """Poll ``pred`` until true or timeout; returns its last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


class Inbox:
    """Thread-safe list of received payloads for a subscriber callback."""

    def __init__(self) -> None:
        self.items: list[bytes] = []
        self._lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.items.append(sample.payload.to_bytes())

    def __len__(self) -> int:
        with self._lock:
            return len(self.items)


def test_named_configs_load_with_scouting_off():
    for name in ("peer", "secure", "secure_client"):
        conf = load_config(name)
        assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
        assert json.loads(conf.get_json("mode")) == "peer"
    conf = load_config("secure")
    assert json.loads(conf.get_json("access_control/enabled")) is True
    ca = json.loads(conf.get_json("transport/link/tls/root_ca_certificate"))
    assert ca == str(config_path("secure").parent / "certs" / "ca.pem")     # resolved to the file's folder
    conf = load_config("peer", listen="tcp/127.0.0.1:1234", connect=[])
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/127.0.0.1:1234"]
    with pytest.raises(FileNotFoundError):
        load_config("nonexistent")
    with pytest.raises(ValueError):
        publisher_options("bogus")


def test_peer_state_round_trip_command_and_liveliness():
    spec = robots.get("pupper")
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    hal_conf = load_config("peer", listen=[ep])
    pol_conf = load_config("peer", listen=[], connect=[ep])
    state = RobotState.zeros(spec.default_pose, timestamp=3.5)
    state.gyro = np.array([0.1, -0.2, 0.3])
    ctl = SafetyController(spec)
    states, accepted = Inbox(), []
    with zenoh.open(hal_conf) as hal, zenoh.open(pol_conf) as pol:
        token = hal.liveliness().declare_token(P.liveliness_key(ROBOT_ID, "hal"))
        hal_cmd = hal.declare_subscriber(P.key(ROBOT_ID, "cmd"), lambda s: accepted.append(ctl.receive(s.payload)))
        pol_sub = pol.declare_subscriber(P.key(ROBOT_ID, "state"), states)
        pub = hal.declare_publisher(P.key(ROBOT_ID, "state"), **publisher_options("state"))
        assert wait_until(lambda: pub.matching_status.matching)
        seq = P.SeqCounter()
        sent = P.encode_state(state, seq())
        pub.put(sent)
        assert wait_until(lambda: len(states) == 1)
        got = P.decode(states.items[0], expect=MsgType.STATE)
        assert states.items[0] == sent and got.body.timestamp == 3.5
        np.testing.assert_array_equal(got.body.gyro, state.gyro)
        alive = [str(r.ok.key_expr) for r in pol.liveliness().get(f"virl/{ROBOT_ID}/alive/**", timeout=2.0) if r.ok]
        assert alive == [P.liveliness_key(ROBOT_ID, "hal")]
        # a command back, then a corrupted one: the HAL's safety layer takes one, counts the other
        cmd = JointCommand(np.array(spec.default_pose), np.array(spec.kp), np.array(spec.kd), np.zeros(12),
                           ref_seq=got.seq)
        cmd_pub = pol.declare_publisher(P.key(ROBOT_ID, "cmd"), **publisher_options("cmd"))
        assert wait_until(lambda: cmd_pub.matching_status.matching)
        good = P.encode_command(cmd, seq())
        cmd_pub.put(good)
        cmd_pub.put(good[:-1] + bytes([good[-1] ^ 1]))
        assert wait_until(lambda: len(accepted) == 2)
        assert accepted == [True, False] and ctl.rejected == {"bad_crc": 1}
        token.undeclare()
        assert wait_until(lambda: not list(pol.liveliness().get(f"virl/{ROBOT_ID}/alive/**", timeout=1.0)))
        for e in (pol_sub, hal_cmd, pub, cmd_pub):
            e.undeclare()


# ----------------------------------------------------------------------------- secure config

def _make_certs(d) -> None:
    """A throwaway CA and a leaf certificate for 127.0.0.1 / localhost, signed by it."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    valid = dict(not_valid_before=now - datetime.timedelta(minutes=5), not_valid_after=now + datetime.timedelta(hours=1))

    def build(subject: str, issuer: x509.Name, pub, sign_key, ca: bool, exts=()) -> x509.Certificate:
        b = (x509.CertificateBuilder().subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
             .issuer_name(issuer).public_key(pub).serial_number(x509.random_serial_number())
             .not_valid_before(valid["not_valid_before"]).not_valid_after(valid["not_valid_after"])
             .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
        for ext in exts:
            b = b.add_extension(ext, critical=False)
        return b.sign(sign_key, hashes.SHA256())

    ca_key, leaf_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "virl test CA")])
    ca = build("virl test CA", ca_name, ca_key.public_key(), ca_key, True)
    leaf = build("hal", ca_name, leaf_key.public_key(), ca_key, False, [
        x509.SubjectAlternativeName([x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
        x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
    ])
    pem = serialization.Encoding.PEM
    (d / "ca.pem").write_bytes(ca.public_bytes(pem))
    (d / "hal.pem").write_bytes(leaf.public_bytes(pem))
    (d / "hal.key").write_bytes(leaf_key.private_bytes(pem, serialization.PrivateFormat.PKCS8,
                                                       serialization.NoEncryption()))
    other_key = ec.generate_private_key(ec.SECP256R1())                 # a CA nobody trusts
    (d / "other_ca.pem").write_bytes(build("other", ca_name, other_key.public_key(), other_key, True).public_bytes(pem))


def _make_certs_openssl(d) -> None:
    """The same files as _make_certs, with the openssl command-line tool."""
    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True, timeout=60)

    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    run("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "1", "-subj", "/CN=virl test CA",
        "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign")
    run("req", *ec, "-keyout", "hal.key", "-out", "hal.csr", "-subj", "/CN=hal")
    (d / "leaf.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=critical,CA:FALSE\n"
                                "extendedKeyUsage=serverAuth,clientAuth\n")
    run("x509", "-req", "-in", "hal.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
        "-out", "hal.pem", "-days", "1", "-extfile", "leaf.ext")
    run("req", "-x509", *ec, "-keyout", "other_ca.key", "-out", "other_ca.pem", "-days", "1", "-subj", "/CN=other")


@pytest.fixture(scope="module", params=["cryptography", "openssl"])
def secure_setup(request, tmp_path_factory):
    d = tmp_path_factory.mktemp(f"zenoh_secure_{request.param}")
    if request.param == "cryptography":
        pytest.importorskip("cryptography")
        _make_certs(d)
    else:
        if shutil.which("openssl") is None:
            pytest.skip("no openssl command")
        _make_certs_openssl(d)
    (d / "credentials.txt").write_text("policy:policy-pw\nmonitor:monitor-pw\noperator:operator-pw\n")
    ep = f"tls/127.0.0.1:{free_port()}"
    hal_conf = load_config("secure", listen=[ep], overrides={
        "transport/link/tls/root_ca_certificate": str(d / "ca.pem"),
        "transport/link/tls/listen_certificate": str(d / "hal.pem"),
        "transport/link/tls/listen_private_key": str(d / "hal.key"),
        "transport/auth/usrpwd/dictionary_file": str(d / "credentials.txt"),
    })

    def client(user, password, ca="ca.pem"):
        return load_config("secure_client", connect=[ep], overrides={
            "transport/link/tls/root_ca_certificate": str(d / ca),
            "transport/auth/usrpwd/user": user, "transport/auth/usrpwd/password": password,
        })

    return hal_conf, client


def test_secure_only_authenticated_policy_user_may_put_on_cmd(secure_setup):
    hal_conf, client = secure_setup
    cmd_key, estop_key = P.key(ROBOT_ID, "cmd"), P.key(ROBOT_ID, "estop")
    cmds, estops = Inbox(), Inbox()
    with zenoh.open(hal_conf) as hal:
        subs = [hal.declare_subscriber(cmd_key, cmds), hal.declare_subscriber(estop_key, estops)]
        # 1. no credentials / wrong password / untrusted CA: the link is refused
        for user, pw, ca in ((None, None, "ca.pem"), ("policy", "wrong", "ca.pem"),
                             ("policy", "policy-pw", "other_ca.pem")):
            with zenoh.open(client(user, pw, ca)) as s:
                time.sleep(0.3)
                assert list(s.info.peers_zid()) == [], (user, ca)
                s.put(cmd_key, b"from " + str(user).encode())
        # 2. authenticated monitor: sees the subscriber, yet its cmd put is denied at ingress
        with zenoh.open(client("monitor", "monitor-pw")) as s:
            assert wait_until(lambda: list(s.info.peers_zid()) == [hal.zid()])
            pub = s.declare_publisher(cmd_key)
            assert wait_until(lambda: pub.matching_status.matching)
            pub.put(b"monitor cmd")
            s.put(estop_key, b"monitor estop")              # sent after the cmd, same link
            assert wait_until(lambda: len(estops) == 1)
            pub.undeclare()
        # 3. the policy user may command
        with zenoh.open(client("policy", "policy-pw")) as s:
            assert wait_until(lambda: list(s.info.peers_zid()) == [hal.zid()])
            pub = s.declare_publisher(cmd_key)
            assert wait_until(lambda: pub.matching_status.matching)
            pub.put(b"policy cmd")
            assert wait_until(lambda: len(cmds) >= 1)
            pub.undeclare()
        time.sleep(0.2)
        assert cmds.items == [b"policy cmd"]
        assert estops.items == [b"monitor estop"]
        for sub in subs:
            sub.undeclare()


def test_secure_monitor_can_read_state(secure_setup):
    hal_conf, client = secure_setup
    states = Inbox()
    with zenoh.open(hal_conf) as hal, zenoh.open(client("monitor", "monitor-pw")) as mon:
        sub = mon.declare_subscriber(P.key(ROBOT_ID, "state"), states)
        pub = hal.declare_publisher(P.key(ROBOT_ID, "state"))
        assert wait_until(lambda: pub.matching_status.matching)
        data = P.encode_state(RobotState.zeros(), 1)
        pub.put(data)
        assert wait_until(lambda: len(states) == 1) and states.items[0] == data
        sub.undeclare()
        pub.undeclare()
