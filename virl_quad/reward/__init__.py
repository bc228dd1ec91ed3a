"""VIRL reward: a learned distance between the agent's video and a single demonstration video.

Frames are 48x48 grayscale, uint8 (or float in [0, 1]). Typical use in the
training loop (Algorithm 1 of the paper)::

    from virl_quad.reward import RewardConfig, build_reward

    rm = build_reward(RewardConfig(), demo_frames, other_clips=None, seed=0)
    state = rm.stream_state(num_envs)
    # per env step: frame t of each env; reset marks envs whose episode starts at this frame
    r, state = rm.stream_step(agent_frames, expert_frames, state, reset_mask)
    # per iteration: store the rollout, train the distance, recompute the rollout's rewards
    rm.add_rollout(agent[T, N], expert[T, N], dones[T, N])
    losses = rm.update(num_updates)
    rewards = rm.recompute(agent, expert, dones, start_state, start_reset)

See :mod:`virl_quad.reward.base` for the reset conventions and
:class:`RewardConfig` for every setting (paper numbers as defaults).
"""

from virl_quad.reward.config import NEGATIVE_PAIRS, POSITIVE_PAIRS, VARIANTS, RewardConfig
from virl_quad.reward.dataset import EpisodeStore
from virl_quad.reward.base import RewardModel, StreamState
from virl_quad.reward.reward import build_reward, from_state_dict, load_reward

__all__ = ["RewardConfig", "build_reward", "from_state_dict", "load_reward", "RewardModel", "StreamState", "EpisodeStore",
           "VARIANTS", "POSITIVE_PAIRS", "NEGATIVE_PAIRS"]
