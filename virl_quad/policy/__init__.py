"""The policy contract: observation -> action -> joint target, shared by training and the robot.

One package, used by the training env (:mod:`virl_quad.envs.quadruped`), the exporter and
loader (:mod:`virl_quad.policy_io`) and the policy server (:mod:`virl_quad.deploy.serve`).
It imports only numpy and the robot spec, never a simulator, so the robot side does not
load PyBullet or Gymnasium.

- :mod:`~virl_quad.policy.observation`: the one observation builder and its layout;
- :mod:`~virl_quad.policy.clock`: the phase clock;
- :mod:`~virl_quad.policy.legs`: closed-form leg forward/inverse kinematics;
- :mod:`~virl_quad.policy.tg`: the trajectory generator (gait prior) and its parameters;
- :mod:`~virl_quad.policy.action`: action -> PD targets (clip, TG + residual, rate and joint limits);
- :mod:`~virl_quad.policy.contract`: the facts that define a policy's interface, as metadata.
"""

from virl_quad.policy.action import ActionMap
from virl_quad.policy.clock import PhaseClock
from virl_quad.policy.contract import PolicyContract
from virl_quad.policy.legs import LegKinematics
from virl_quad.policy.observation import policy_block, policy_layout, policy_observation, policy_size, yaw
from virl_quad.policy.tg import TGParams, TrajectoryGenerator

__all__ = ["ActionMap", "PhaseClock", "PolicyContract", "LegKinematics", "TGParams", "TrajectoryGenerator",
           "policy_block", "policy_layout", "policy_observation", "policy_size", "yaw"]
