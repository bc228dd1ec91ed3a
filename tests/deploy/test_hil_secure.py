"""(d) Hardware-in-the-loop under the authenticated config: a running sim HAL on
``deploy/zenoh/secure.json5`` (TLS + user/password + access control, used unchanged), the
policy server on ``secure_client.json5``. A stranger without credentials never reaches the
HAL; an authenticated user without the ``policy`` role is filtered by the ACL; only the
``policy`` user's commands are taken and only the ``operator`` may re-arm.

How the test can tell a dropped command from a delayed one: the forbidden commands carry
``seq = 2**64 - 1``: had one been accepted, every later command of the real server would be
rejected as ``stale_seq`` (and the HAL would damp). The monitor's puts are followed, on the
same link and priority, by an allowed E-stop, so once the E-stop is seen they were handled.
"""

from __future__ import annotations

import datetime
import ipaddress
import shutil
import time

import numpy as np
import pytest
import zenoh

from virl_quad import robots
from virl_quad.deploy import protocol as P
from hil_harness import Monitor, policy_for_tests, start_hal, start_server
from virl_quad.deploy.protocol import JointCommand, MsgType
from virl_quad.deploy.zenoh_config import CONFIG_DIR, free_port, load_config

ROBOT_ID = "pupper-sec"
TIMEOUT = 120.0              # s, generous waits (never asserted as timings)
CREDENTIALS = {"policy": "policy-pw", "monitor": "monitor-pw", "operator": "operator-pw"}


def _write_certs(certs) -> None:
    """A throwaway CA and a HAL certificate for 127.0.0.1 / localhost (cryptography package)."""
    x509 = pytest.importorskip("cryptography.x509")
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key, hal_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "virl hil CA")])

    def cert(name: x509.Name, key, ca: bool, extensions=()) -> x509.Certificate:
        b = (x509.CertificateBuilder().subject_name(name).issuer_name(ca_name).public_key(key.public_key())
             .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
             .not_valid_after(now + datetime.timedelta(hours=2))
             .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
        for e in extensions:
            b = b.add_extension(e, critical=False)
        return b.sign(ca_key, hashes.SHA256())

    hal = cert(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "hal")]), hal_key, False, [
        x509.SubjectAlternativeName([x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
        x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
    ])
    pem = serialization.Encoding.PEM
    certs.mkdir()
    (certs / "ca.pem").write_bytes(cert(ca_name, ca_key, True).public_bytes(pem))
    (certs / "hal.pem").write_bytes(hal.public_bytes(pem))
    (certs / "hal.key").write_bytes(hal_key.private_bytes(pem, serialization.PrivateFormat.PKCS8,
                                                          serialization.NoEncryption()))


@pytest.fixture
def secure_dir(tmp_path):
    """The shipped secure configs, with certificates and credentials where they expect them."""
    _write_certs(tmp_path / "certs")
    shutil.copy(CONFIG_DIR / "secure.json5", tmp_path / "secure.json5")
    client = (CONFIG_DIR / "secure_client.json5").read_text()
    assert 'password: "change-me"' in client
    (tmp_path / "secure_client.json5").write_text(client.replace('password: "change-me"', 'password: "policy-pw"'))
    (tmp_path / "credentials.txt").write_text("".join(f"{u}:{p}\n" for u, p in CREDENTIALS.items()))
    return tmp_path


def _wild_command(seq: int) -> bytes:
    """A well-formed command that would matter if it arrived: huge seq, targets at the limits."""
    spec = robots.get("pupper")
    cmd = JointCommand(np.array(spec.joint_upper), 2 * np.array(spec.kp), np.zeros(12), np.zeros(12))
    return P.encode_command(cmd, seq)


def test_stranger_cannot_command_a_running_secure_hal(secure_dir, tmp_path_factory):
    policy, _ = policy_for_tests(tmp_path_factory.mktemp("sec_policy"))
    ep = f"tls/127.0.0.1:{free_port()}"

    def client(user: str | None, password: str | None) -> zenoh.Config:
        return load_config(secure_dir / "secure_client.json5", connect=[ep], overrides={
            "transport/auth/usrpwd/user": user, "transport/auth/usrpwd/password": password})

    hal = start_hal(ep, ROBOT_ID, "--zenoh", str(secure_dir / "secure.json5"), "--lockstep",
                    "--lockstep-timeout", "2.0", "--arm")
    procs = [hal]
    mon = Monitor(client("monitor", CREDENTIALS["monitor"]), ROBOT_ID)
    try:
        procs.append(start_server(policy, ep, ROBOT_ID, "--zenoh", str(secure_dir / "secure_client.json5")))

        def wait(pred, what: str) -> dict:
            st = mon.wait_status(pred, TIMEOUT)
            logs = "\n".join(p.output() for p in procs)
            assert st and pred(st), f"STATUS never showed {what}; last {st}\n{logs}"
            return st

        # the authenticated policy server drives the robot over TLS
        st = wait(lambda s: s["mode"] == "ACTIVE" and s["applied"] >= 25, "the policy user driving")
        cmd_key, estop_key = P.key(ROBOT_ID, "cmd"), P.key(ROBOT_ID, "estop")
        # 1. no credentials: the session never reaches the HAL
        with zenoh.open(client(None, None)) as stranger:
            time.sleep(0.5)
            assert list(stranger.info.peers_zid()) == []
            for _ in range(5):
                stranger.put(cmd_key, b"stranger junk")
                stranger.put(cmd_key, _wild_command(2**64 - 1))
            stranger.close()
        # 2. authenticated but not 'policy': connected, yet its commands are filtered by the ACL
        assert list(mon.session.info.peers_zid()) != []
        mon.session.put(cmd_key, b"monitor junk")
        mon.session.put(cmd_key, _wild_command(2**64 - 1))
        mon.session.put(P.key(ROBOT_ID, "arm"), P.encode_json(MsgType.ARM, {"robot_id": ROBOT_ID}, 1))
        applied = st["applied"]
        st = wait(lambda s: s["applied"] >= applied + 25, "the server still driving")
        assert st["mode"] == "ACTIVE" and st["rejected"] == {}, st
        mon.session.put(estop_key, P.encode_json(MsgType.ESTOP, {"reason": "marker"}, 2))   # allowed to all
        st = wait(lambda s: s["mode"] == "DAMPING", "the monitor's E-stop")
        assert st["fault"] == "estop: marker", st
        assert st["rejected"] == {} and st["last_seq"] != 2**64 - 1, st            # nothing forbidden arrived
        assert st["events"].get("arm") == 1 and st["rejected_other"] == {}, st      # only the --arm at start
        # 3. only the operator may re-arm; the policy user's junk IS seen (so the zeros above mean "dropped")
        operator = Monitor(client("operator", CREDENTIALS["operator"]), ROBOT_ID)
        try:
            operator.wait_status(lambda s: True, TIMEOUT)
            operator.arm()
            st = wait(lambda s: s["events"].get("arm") == 2, "the operator's ARM")
        finally:
            operator.close()
        with zenoh.open(client("policy", CREDENTIALS["policy"])) as pol:
            pub = pol.declare_publisher(cmd_key)
            deadline = time.monotonic() + TIMEOUT
            while not pub.matching_status.matching and time.monotonic() < deadline:
                time.sleep(0.02)
            pub.put(b"policy junk")
            st = wait(lambda s: s["rejected"].get("bad_size") == 1, "the policy user's junk counted")
            pub.undeclare()
            pol.close()
        assert hal.stop() == 0 and hal.alive() is False
        assert "Traceback" not in "".join(p.output() for p in procs)
    finally:
        mon.close()
        for p in procs:
            p.close()
