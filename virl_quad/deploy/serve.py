"""Policy server: runs an exported TorchScript policy against a HAL over Zenoh.

    python -m virl_quad.deploy.serve --policy policies/pupper_trot.pt [--robot-id pupper-01]

It waits for the HAL's liveliness token, queries its ANNOUNCE and refuses (one line, exit 2)
a robot, joint order, control period or protocol version that the policy was not made for.
Then, for every STATE on ``virl/<id>/state`` it builds the observation with
:func:`virl_quad.policy.observation.policy_observation` (the training builder), runs the
policy and publishes a COMMAND on ``virl/<id>/cmd``: ``q_target`` from
:class:`virl_quad.policy.ActionMap` (the training env's action -> target map: clip, trajectory
generator + residual, rate limit, joint limits), ``kp``/``kd`` from the policy metadata, no
feed-forward, ``ref_seq`` = the state's ``seq``. The phase clock is the ActionMap's
(:class:`virl_quad.policy.PhaseClock`, at the TG's or the demonstration's frequency).

An episode starts as a training episode starts (clock at phase 0, last action 0, the rate
limit from the measured pose, the heading's start yaw = the state's yaw) at the first state
the HAL flags ACTIVE (``STATE_FLAG_ACTIVE``: the answer will be applied). States before it
(IDLE, the RAMP to the default pose, DAMPING) are answered as an episode's first step from
that state, without starting it, so a HAL that ramps for 2 s, or is re-armed, starts the
policy at phase 0. A HAL whose ANNOUNCE lacks ``active_flag`` gets the old behaviour: the
episode runs from the first state served (logged at start).

States with NaN/inf or a non-unit quaternion are skipped (not answered) and counted; so
are undecodable or reordered ones. When the HAL's token disappears the server stops
commanding and waits for it to come back (then checks its ANNOUNCE again).
"""

from __future__ import annotations

import gc
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from virl_quad.cli import UserError, opt, parse, run_main
from virl_quad.deploy import protocol as P
from virl_quad.deploy._zenoh_io import Log, SeqPublisher, StopFlag, open_config, open_session, undeclare_all
from virl_quad.deploy.protocol import MsgType, ProtocolError
from virl_quad.deploy.zenoh_config import DEFAULT_CONNECT
from virl_quad.policy.action import ActionMap
from virl_quad.policy.observation import policy_observation, yaw

_POLICIES = Path(__file__).resolve().parents[2] / "policies"
#: Policies served when --policy is not given, the first one present: the VIRL trot of the
#: training pipeline (policies/README.md), then the shipped behaviour-cloned tracker
#: (``python -m virl_quad.distill``: walks on the nominal robot; not learned from video).
SHIPPED_POLICIES: tuple[Path, ...] = (_POLICIES / "pupper_trot.pt", _POLICIES / "pupper_trot_tracker_bc.pt")


def default_policy() -> Path:
    """The first of :data:`SHIPPED_POLICIES` that exists (else the first, for the error message)."""
    return next((p for p in SHIPPED_POLICIES if p.is_file()), SHIPPED_POLICIES[0])




@dataclass
class ServeConfig:
    """Settings of one policy-server process."""

    policy: str = opt("", "exported policy NAME.pt, NAME.json beside it (empty: the first present of "
                      + ", ".join(str(x.relative_to(_POLICIES.parent)) for x in SHIPPED_POLICIES) + ")")
    robot_id: str | None = opt(None, "the HAL's robot id (unset: <policy robot>-01)")
    zenoh: str = opt("peer", "Zenoh config: name in deploy/zenoh/ or a .json5 path")
    connect: list[str] | None = opt(None, f"endpoint of the HAL (unset: the config's, else {DEFAULT_CONNECT})")
    listen: list[str] | None = opt(None, "listen endpoint (unset: none)")
    wait: float = opt(30.0, "s to wait for the HAL at start (0: forever)")
    threads: int = opt(1, "torch intra-op threads (1 is fastest for small MLPs)")
    quiet: bool = opt(False, "no log lines on stderr")


class PolicyRunner:
    """State bytes in, command bytes out: the policy side of the protocol, without Zenoh."""

    def __init__(self, policy: Any) -> None:
        """``policy``: a :class:`virl_quad.policy_io.LoadedPolicy`."""
        self.policy = policy
        self.spec = policy.spec
        meta = policy.meta
        self.kp = np.asarray(meta["kp"], dtype=np.float64)            # N·m/rad
        self.kd = np.asarray(meta["kd"], dtype=np.float64)            # N·m·s/rad
        self.actions = ActionMap(self.spec, policy.contract)          # the env's action -> target map
        self.with_phase = policy.contract.with_phase
        self.counts: Counter[str] = Counter()   # served, skipped reasons
        self.gate_on_active = True              # start the episode only on ACTIVE-flagged states
        self._lock = threading.Lock()
        self._seq = P.SeqCounter()
        self._encode = P.CommandEncoder(self.kp, self.kd, np.zeros(P.NUM_JOINTS))   # no feed-forward
        self._zero_action = np.zeros(self.actions.size)
        self._zero_action.flags.writeable = False
        self.reset()

    def reset(self) -> None:
        """Start again: no episode running (a new HAL session)."""
        with self._lock:
            self.k = 0                                  # commands applied in this episode
            self.started = False                        # an ACTIVE state has started the episode
            self.start_yaw = 0.0                        # rad, the heading's origin
            self.last_state_seq = -1

    @property
    def last_action(self) -> np.ndarray:
        """The last applied action, clipped and unscaled (zero before the episode starts)."""
        return self.actions.last_action if self.started else self._zero_action

    def phase(self) -> float | None:
        """Clock phase in [0, 1) of the next command (None if the policy has no clock)."""
        if not self.with_phase:
            return None
        return self.actions.phase if self.started else 0.0

    def handle(self, data: bytes) -> tuple[bytes | None, str]:
        """One STATE message -> (COMMAND message or None, skip reason or "").

        Never raises: malformed, reordered or non-finite states are skipped with a reason."""
        try:
            seq, flags, f = P.decode_state_values(data)
        except ProtocolError as e:
            return self._skip(f"bad_message:{e.reason}")
        with self._lock:
            if seq <= self.last_state_seq:
                return self._skip("stale_state")
            live = not self.gate_on_active or bool(flags & P.STATE_FLAG_ACTIVE)
            if not live:                                         # not applied: no episode runs
                self.started = False
                self.k = 0
            quat = f[P.STATE_QUAT]
            x, y, z, w = quat.tolist()
            norm2 = x * x + y * y + z * z + w * w
            if not math.isfinite(norm2):
                return self._skip("non_finite_state")
            if not 0.81 < norm2 < 1.21:                          # |quat| outside [0.9, 1.1]
                return self._skip("bad_quaternion")
            quat = quat / math.sqrt(norm2)
            fresh = not self.started                             # this state is an episode's first
            start_yaw = yaw(quat) if fresh else self.start_yaw
            q = f[P.STATE_Q]
            try:                                                # raises on NaN/inf in gyro, q, dq
                obs = policy_observation(self.spec, quat, f[P.STATE_GYRO], q, f[P.STATE_DQ], self.last_action,
                                         self.phase(), start_yaw)
            except ValueError:
                return self._skip("non_finite_state")
            self.last_state_seq = seq
            try:
                action = self.policy.act(obs)
            except ValueError:                                  # the policy produced NaN/inf
                return self._skip("policy_non_finite")
            if fresh:                                            # as the env's reset: pose, phase 0, yaw
                self.actions.reset(q, 0.0)
                self.start_yaw = start_yaw
            q_target = self.actions.step(action)                # rad, rate- and joint-limited
            if live:
                self.started = True
                self.k += 1
            out = self._encode(q_target, seq, self._seq())
        self.counts["served"] += 1
        return out, ""

    def _skip(self, reason: str) -> tuple[None, str]:
        self.counts[reason] += 1
        return None, reason


def check_announce(body: Any, meta: dict[str, Any], robot_id: str) -> str:
    """'' if the HAL's ANNOUNCE matches the policy metadata, else what differs (one line)."""
    if not isinstance(body, dict):
        return "the HAL's announce is not a JSON object"
    checks = [
        ("protocol_version", body.get("protocol_version"), P.PROTOCOL_VERSION),
        ("robot", body.get("robot"), meta.get("robot")),
        ("robot_id", body.get("robot_id"), robot_id),
        ("joint_order", body.get("joint_order"), meta.get("joint_names")),
    ]
    for name, got, want in checks:
        if got != want:
            return f"HAL {name} {got!r} does not match the policy's {want!r}"
    dt = body.get("control_dt")
    if not isinstance(dt, (int, float)) or abs(float(dt) - float(meta.get("control_dt", -1))) > 1e-9:
        return f"HAL control_dt {dt!r} s does not match the policy's {meta.get('control_dt')!r} s"
    return ""


def query_announce(session: zenoh.Session, robot_id: str, timeout: float = 2.0) -> dict[str, Any] | None:
    """The HAL's ANNOUNCE body, or None if no valid reply came within ``timeout`` s."""
    for reply in session.get(P.key(robot_id, "announce"), timeout=timeout):
        if reply.ok is None:
            continue
        try:
            msg = P.decode(reply.ok.payload, expect=MsgType.ANNOUNCE)
        except ProtocolError:
            continue
        return msg.body  # type: ignore[return-value]
    return None


class Server:
    """Zenoh side of the policy server: HAL presence, announce check, state -> command."""

    def __init__(self, runner: PolicyRunner, session: zenoh.Session, robot_id: str, log: Log) -> None:
        self.runner, self.session, self.robot_id, self.log = runner, session, robot_id, log
        self.enabled = threading.Event()       # HAL present and its announce checked
        self.hal_seen = threading.Event()      # alive/hal token present (set by the callback)
        self.errors = 0
        self.work_us = np.zeros(4096)          # µs from state received to command published (ring)
        self.work_n = 0
        self.cmd_pub = SeqPublisher(session, robot_id, "cmd")
        self._entities: list[Any] = [self.cmd_pub]
        self._entities.append(session.liveliness().declare_subscriber(
            P.liveliness_key(robot_id, "hal"), self._on_hal, history=True))
        self._entities.append(session.declare_subscriber(P.key(robot_id, "state"), self._on_state))

    def _on_hal(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.hal_seen.set()
        else:
            self.hal_seen.clear()
            if self.enabled.is_set():
                self.enabled.clear()
                self.log("HAL gone: not sending commands")

    def _on_state(self, sample: zenoh.Sample) -> None:
        if not self.enabled.is_set():
            return
        t0 = time.perf_counter_ns()
        try:
            out, reason = self.runner.handle(sample.payload.to_bytes())
            if out is not None:
                self.cmd_pub.pub.put(out)
                self.work_us[self.work_n % len(self.work_us)] = (time.perf_counter_ns() - t0) / 1e3
                self.work_n += 1
            elif reason:
                self.log.once(reason, f"skipping state(s): {reason} (counted)")
        except Exception as e:   # never crash in a callback: count, log once
            self.errors += 1
            self.log.once(f"err-{type(e).__name__}", f"error while serving a state (counted): {e!r}")

    def verify(self, timeout: float) -> bool:
        """Query the HAL's announce and check it; raise UserError on a mismatch."""
        body = query_announce(self.session, self.robot_id, timeout)
        if body is None:
            return False
        problem = check_announce(body, self.runner.policy.meta, self.robot_id)
        if problem:
            raise UserError(problem)
        self.runner.gate_on_active = bool(body.get("active_flag"))
        if not self.runner.gate_on_active:
            self.log("the HAL does not flag ACTIVE states: the episode (phase clock) runs from the first state served")
        return True

    def run(self, stop: StopFlag, wait: float) -> None:
        """Serve until ``stop``; UserError if no HAL shows up within ``wait`` s (0: forever)."""
        deadline = time.monotonic() + wait if wait > 0 else float("inf")
        token = None
        while not stop.is_set():
            if not self.enabled.is_set() and self.hal_seen.is_set() and self.verify(timeout=2.0):
                self.runner.reset()
                if token is None:
                    token = self.session.liveliness().declare_token(P.liveliness_key(self.robot_id, "policy"))
                    self._entities.append(token)
                self.enabled.set()
                self.log(f"serving robot {self.robot_id!r}")
            if token is None and time.monotonic() > deadline:
                raise UserError(f"no HAL for robot id {self.robot_id!r} answered within {wait:g} s")
            stop.wait(0.05)

    def work_summary(self) -> str:
        """Median / p99 / max of the server's own time per command (µs), over the last 4096."""
        w = self.work_us[:min(self.work_n, len(self.work_us))]
        if not len(w):
            return "no commands timed"
        return f"compute per command: median {np.median(w):.0f} µs, p99 {np.percentile(w, 99):.0f} µs, max {w.max():.0f} µs"

    def close(self) -> None:
        """Stop serving and undeclare everything (never raises)."""
        self.enabled.clear()
        undeclare_all(self._entities)


def load(path: str) -> Any:
    """Load and check a policy; UserError or ValueError (one line) for a missing or bad file."""
    if not Path(path).is_file():
        raise UserError(f"policy file {path} does not exist (train and export one, or pass --policy)")
    from virl_quad.policy_io import load_policy                # torch: only for a file that exists
    try:
        policy = load_policy(path)
    except (KeyError, TypeError, AttributeError) as e:   # metadata with missing or mistyped members
        raise UserError(f"policy metadata of {path} is incomplete ({type(e).__name__}: {e})") from None
    return speed_up(policy)


def speed_up(policy: Any, warmup: int = 20) -> Any:
    """Freeze the TorchScript module (weights inlined as constants: ``act`` about 20 % faster
    for the exported MLP, 38 against 47 µs here) if the frozen module gives the same actions,
    then warm it up so that the first state is not slowed down by TorchScript's profiling runs.
    Nothing to do when the policy runs on the numpy fast path of
    :func:`virl_quad.policy_io.load_policy` (17 µs here): only other structures go through torch."""
    if policy.fast is not None:   # served in numpy: the module is only its reference
        return policy
    import torch

    probe = np.random.default_rng(0).normal(size=policy.meta["observation"]["size"]).astype(np.float32)
    want = policy.act(probe)
    original = policy.module
    try:
        policy.module = torch.jit.freeze(original.eval())
        if not np.allclose(policy.act(probe), want, rtol=1e-5, atol=1e-6):
            policy.module = original
    except Exception:   # freezing is an optimisation only: keep the module as exported
        policy.module = original
    for _ in range(warmup):
        policy.act(probe)
    return policy


def main(config: ServeConfig) -> int:
    """Serve ``config.policy`` until SIGINT/SIGTERM; returns the exit code (bad input: UserError,
    ValueError or FileNotFoundError, printed as one line with exit code 2 by run_main)."""
    path = config.policy or str(default_policy())
    policy = load(path)                                 # a missing file is refused before torch loads
    import torch

    torch.set_num_threads(max(1, config.threads))
    robot_id = P.check_robot_id(config.robot_id or f"{policy.meta['robot']}-01")
    conf = open_config(config.zenoh, listen=config.listen or [], connect=config.connect)
    if not config.connect and conf.get_json("connect/endpoints").strip() in ("[]", "null"):
        conf.insert_json5("connect/endpoints", f'["{DEFAULT_CONNECT}"]')
    log = Log("serve", quiet=config.quiet)
    zenoh.init_log_from_env_or("error")
    runner = PolicyRunner(policy)
    # Real-time hygiene: move everything loaded so far (torch alone is ~10^5 objects) out of
    # the collector's reach, so a collection triggered while serving scans only new objects.
    gc.collect()
    gc.freeze()
    meta = policy.meta
    log(f"policy {path} (reward: {meta.get('reward', 'not recorded')}) for {meta['robot']} "
        f"({len(meta['joint_names'])} joints, {1 / float(meta['control_dt']):g} Hz, "
        f"{'trajectory generator' if policy.contract.tg is not None else 'no trajectory generator'}); "
        f"waiting for HAL {robot_id!r}")
    with StopFlag() as stop:
        with open_session(conf) as session:
            server = Server(runner, session, robot_id, log)
            try:
                server.run(stop, config.wait)
            finally:
                server.close()
                session.close()
    skipped = {k: v for k, v in runner.counts.items() if k != "served"}
    log(f"stopped: {runner.counts['served']} commands sent, skipped {skipped or 'none'}, errors {server.errors}; "
        f"{server.work_summary()}")
    return 0


def config_from_args(argv: list[str] | None = None) -> ServeConfig:
    """Parse the command line into a :class:`ServeConfig` (its fields are the options)."""
    return parse(ServeConfig, argv, __doc__.split("\n\n")[0], "python -m virl_quad.deploy.serve")


if __name__ == "__main__":
    run_main(lambda: main(config_from_args()))
