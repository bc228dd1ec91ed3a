"""What defines a policy's interface: how its actions become joint targets and what it observes.

A :class:`PolicyContract` is written by the env's configuration (training), saved in the
checkpoint and the exported policy's metadata (:meth:`PolicyContract.to_metadata`), and read
back by the loader and the policy server (:meth:`PolicyContract.from_metadata`), which
refuse a contract that this version cannot honour with one ValueError line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from virl_quad.policy.observation import policy_layout
from virl_quad.policy.tg import TGParams, TrajectoryGenerator, modulation_facts
from virl_quad.robots.spec import RobotSpec


def _positive(name: str, value: object, allow_none: bool = False) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"policy {name} must be a positive number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class PolicyContract:
    """Action -> joint target and observation facts of one policy (SI units)."""

    action_scale: float                  # rad per unit action (joint residuals)
    action_clip: float                   # |a| is clipped to this before use
    max_target_step: float | None        # rad per control period a PD target may move; None: unlimited
    control_dt: float                    # s, control period
    tg: TGParams | None = None           # trajectory generator (actions: 12 residuals + 2 modulation); None: none
    phase_hz: float | None = None        # Hz, clock of a policy without a TG (a demonstration's cycle
                                         # frequency); None with no TG: no phase in the observation

    def __post_init__(self) -> None:
        _positive("action_scale", self.action_scale)
        _positive("action_clip", self.action_clip)
        _positive("max_target_step", self.max_target_step, allow_none=True)
        _positive("control_dt", self.control_dt)
        _positive("phase_hz", self.phase_hz, allow_none=True)
        if self.tg is not None and not isinstance(self.tg, TGParams):
            raise ValueError(f"policy tg must be TGParams or None, got {type(self.tg).__name__}")
        if self.tg is not None and self.phase_hz is not None:
            raise ValueError("a policy with a TG runs its clock at the TG's frequency: phase_hz must be None")

    @property
    def action_size(self) -> int:
        """Entries of an action: 12 joint residuals, + 2 TG modulation entries with a TG."""
        return 14 if self.tg is not None else 12

    @property
    def clock_hz(self) -> float | None:
        """Hz, frequency of the phase clock at modulation 1 (None: no clock)."""
        return self.tg.frequency if self.tg is not None else self.phase_hz

    @property
    def with_phase(self) -> bool:
        """Whether the observation carries the clock's phase."""
        return self.clock_hz is not None

    @property
    def layout(self) -> list[tuple[str, int, float]]:
        """(name, size, scale) of the observation blocks."""
        return policy_layout(self.with_phase, self.action_size)

    @property
    def observation_size(self) -> int:
        """Entries of the policy observation."""
        return sum(n for _, n, _ in self.layout)

    def env_overrides(self) -> dict:
        """The ``virl_quad.envs.make`` options that make an env with this contract (the phase
        clock of a policy without a TG follows the env's demonstration)."""
        return {"action_scale": self.action_scale, "action_clip": self.action_clip,
                "max_target_step": self.max_target_step, "tg": self.tg}

    def to_metadata(self) -> dict:
        """The contract as policy-metadata entries (JSON types)."""
        return {
            "action_scale": self.action_scale,              # rad per unit action
            "action_clip": self.action_clip,                # |a| clipped to this
            "max_target_step": self.max_target_step,        # rad per control period (None: unlimited)
            "control_dt": self.control_dt,                  # s
            "action_size": self.action_size,
            "tg": None if self.tg is None else self.tg.to_dict(),
            "tg_modulation": None if self.tg is None else modulation_facts(),
            "phase_hz": self.phase_hz,                      # Hz (None: the TG's, or no clock)
            "observation": {
                "size": self.observation_size,
                "with_phase": self.with_phase,
                "layout": [{"name": n, "size": k, "scale": s} for n, k, s in self.layout],
            },
        }

    @classmethod
    def from_metadata(cls, meta: dict, spec: RobotSpec) -> PolicyContract:
        """The contract of a policy's metadata, checked against ``spec`` and this version's code.

        ValueError (one line) when an entry is missing or malformed, when the metadata lacks the
        TG its action size or observation needs, or when its TG, action size or observation
        layout contradict each other or this version."""
        if not isinstance(meta, dict):
            raise ValueError("policy metadata is not a JSON object")
        for key in ("action_scale", "action_clip", "control_dt", "observation"):
            if key not in meta:
                raise ValueError(f"policy metadata lacks {key!r}")
        dt = _positive("control_dt", meta["control_dt"])
        if abs(dt - spec.control_dt) > 1e-9:
            raise ValueError(f"policy control period {dt} s differs from {spec.name}'s {spec.control_dt} s")
        obs = meta["observation"]
        if not isinstance(obs, dict) or not isinstance(obs.get("layout"), list):
            raise ValueError("policy metadata 'observation' lacks its layout")
        seen = {b.get("name"): b.get("size") for b in obs["layout"] if isinstance(b, dict)}
        size = meta.get("action_size", seen.get("last_action", 12))
        if size not in (12, 14) or isinstance(size, bool):
            raise ValueError(f"policy action size {size!r} is not 12 (joint offsets) or 14 (TG residuals + modulation)")
        tg_dict = meta.get("tg")
        if tg_dict is None and 14 in (size, seen.get("last_action")):
            raise ValueError("policy metadata lacks its trajectory generator ('tg'): its 14 actions need one")
        if seen.get("last_action", size) != size:
            raise ValueError(f"policy action size {size} contradicts its observed last action of {seen['last_action']}")
        if tg_dict is None and "phase_sin_cos" in seen and meta.get("phase_hz") is None:
            raise ValueError("policy metadata lacks its trajectory generator ('tg') or phase clock ('phase_hz'): "
                             "its observation has a phase")
        tg = None
        if tg_dict is not None:
            try:
                tg = TGParams.from_dict(tg_dict)
                TrajectoryGenerator(spec, tg)
            except ValueError as e:
                raise ValueError(f"policy trajectory generator: {e}") from None
            if size != 14:
                raise ValueError(f"policy has a trajectory generator but {size} actions (a TG policy has 14)")
            if meta.get("tg_modulation") != modulation_facts():
                raise ValueError(f"policy TG modulation {meta.get('tg_modulation')} differs from this version's "
                                 f"{modulation_facts()}")
            if meta.get("phase_hz") is not None:
                raise ValueError("policy has both a trajectory generator and a separate phase clock ('phase_hz')")
        contract = cls(action_scale=_positive("action_scale", meta["action_scale"]),
                       action_clip=_positive("action_clip", meta["action_clip"]),
                       max_target_step=_positive("max_target_step", meta.get("max_target_step"), allow_none=True),
                       control_dt=spec.control_dt, tg=tg,
                       phase_hz=None if tg is not None else _positive("phase_hz", meta.get("phase_hz"), True))
        want = [{"name": n, "size": k, "scale": s} for n, k, s in contract.layout]
        if obs.get("layout") != want or obs.get("size") != contract.observation_size:
            raise ValueError("policy observation layout differs from this version's observation builder")
        return contract
