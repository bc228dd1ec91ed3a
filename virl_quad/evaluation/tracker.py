"""A privileged reference tracker: the controller that knows the reference joint angles.

Not a policy (a policy sees only proprioception and never the reference): a yardstick.
Its ground-truth score estimates what the robot model can reach on a demonstration, and
its camera frames are a physically simulated good imitation to show a distance model.

    target = q_ref(t + lead) + gain * (q_ref(t) - q)          (rad)

sent through the environment's own action space (scale, clip, rate limit, PD gains,
torque limits; with a trajectory generator as the residual on its next pose): PD tracking made (1 + gain) times stiffer by feedback on the target,
with the feed-forward reference ``lead`` s ahead to make up for the PD lag.
"""

from __future__ import annotations

import numpy as np

#: Best of a sweep on the Pupper trot with randomisation on (bench/tracking_bound.py).
DEFAULT_GAIN = 2.0     # feedback gain on the joint error, dimensionless
DEFAULT_LEAD = 0.08    # s


def tracker_action(env, gain: float = DEFAULT_GAIN, lead: float = DEFAULT_LEAD, motion=None,
                   delay: float = 0.0, q: np.ndarray | None = None) -> np.ndarray:
    """The action for the current step of ``env`` (a ``virl_quad.envs`` environment), in the
    env's units (target offset / action scale). ``motion``: what to track (default: the
    demonstration's reference motion); ``delay`` (s): track it that much behind the
    demonstration clock (half a cycle: the right motion out of phase); ``q`` (rad): the joint
    angles to feed back (default: the simulator's true ones)."""
    u = env.unwrapped
    motion = motion if motion is not None else u.demo.motion
    if motion is None:
        raise ValueError("the demonstration has no reference motion to track")
    t = u.demo_step / u.demo.fps - delay             # s, demonstration clock
    q_ref = motion.state_at(t).q
    q = u.state.q if q is None else np.asarray(q, dtype=np.float64)
    target = motion.state_at(t + lead).q + gain * (q_ref - q)
    residual = (target - u.actions.base_target()) / u.action_scale    # base: default pose, or the TG's next pose
    return np.concatenate([residual, np.zeros(u.actions.size - 12)])  # TG modulation (if any) left at 1
