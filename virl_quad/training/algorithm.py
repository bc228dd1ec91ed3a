"""Algorithm 1 of VIRL on rsl-rl's PPO, without forking rsl-rl.

``VirlPPO`` is named in the rsl-rl config (``algorithm.class_name``). The stock
rollout loop calls ``act`` / ``process_env_step`` / ``compute_returns`` /
``update``; this subclass adds, per iteration:

1. while collecting: hand each step's agent and expert frames to the reward source
   (``process_env_step``),
2. before returns are computed: the reward source adds finished episodes to the
   distance model's dataset, runs M model updates and recomputes the whole
   rollout's rewards with the updated model (``compute_returns``),
3. the recomputed rewards replace the stored ones, with rsl-rl's time-out
   bootstrap (``+ gamma * V(s) * time_out``) applied again, then PPO as usual.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict


class _ActorRate:
    """Adam over actor and critic as rsl-rl's KL-adaptive schedule sees it: ``param_groups``
    lists the actor's group alone, so the schedule sets the actor's learning rate and the
    critic keeps its own; everything else is the optimizer's."""

    def __init__(self, optimizer: torch.optim.Optimizer) -> None:
        self.optimizer = optimizer

    @property
    def param_groups(self) -> list[dict]:
        """The actor's parameter group."""
        return self.optimizer.param_groups[:1]

    def __getattr__(self, name: str):
        if name == "optimizer":      # not set yet (a copy being built): no recursion
            raise AttributeError(name)
        return getattr(self.optimizer, name)


class VirlPPO(PPO):
    """PPO whose rewards come from a :class:`~virl_quad.training.rewards.RolloutReward`.

    ``critic_learning_rate``: a fixed Adam rate of the critic (None: the critic shares the
    actor's KL-adaptive rate, as in rsl-rl)."""

    def __init__(self, *args, critic_learning_rate: float | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if critic_learning_rate:
            self.optimizer = _ActorRate(torch.optim.Adam([
                {"params": list(self.actor.parameters()), "lr": self.learning_rate},
                {"params": list(self.critic.parameters()), "lr": float(critic_learning_rate)}]))
        self.reward_source = None  # attached by the runner: needs the demonstration
        self._time_outs: list[torch.Tensor] = []
        self.last_reward_info: dict[str, float] = {}
        self.frozen_updates = 0    # coming updates that fit the critic alone (see freeze_actor)
        #: torch's CPU threads while the distance model and PPO learn (the env workers wait
        #: then, their cores free); None: torch's setting stays as it is
        self.learn_threads: int | None = None
        #: the warm-started actor's weights and the fraction of the way back to them that the
        #: actor's weights move after every PPO update (see anchor_actor)
        self.anchor: list[torch.Tensor] | None = None
        self.prior_pull = 0.0

    @contextlib.contextmanager
    def learning_threads(self) -> Iterator[None]:
        """Within: torch runs on :attr:`learn_threads` CPU threads (the env workers wait)."""
        before = torch.get_num_threads()
        if self.learn_threads:
            torch.set_num_threads(self.learn_threads)
        try:
            yield
        finally:
            torch.set_num_threads(before)

    def attach_reward(self, source) -> None:
        """Set the reward source (see virl_quad.training.rewards)."""
        self.reward_source = source

    def process_env_step(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor,
                         extras: dict) -> None:
        """Record the step's frames for the reward, then store the transition as PPO does."""
        if self.reward_source is None:
            raise RuntimeError("VirlPPO needs a reward source: call attach_reward() before training")
        self.reward_source.observe(obs, rewards, dones, extras)
        self._time_outs.append(extras["time_outs"].to(self.device).float())
        super().process_env_step(obs, rewards, dones, extras)

    def compute_returns(self, obs: TensorDict) -> None:
        """Update the distance model, recompute this rollout's rewards, then GAE as usual."""
        st = self.storage
        with self.learning_threads(), torch.inference_mode(False), torch.enable_grad():
            new_rewards, info = self.reward_source.finish()
        new_rewards = new_rewards.to(self.device, torch.float32).reshape(st.rewards.shape)
        time_outs = torch.stack(self._time_outs).reshape(st.rewards.shape)
        self._time_outs = []
        st.rewards.copy_(new_rewards + self.gamma * st.values * time_outs)
        info["reward_mean"] = float(new_rewards.mean())
        self.last_reward_info = info
        super().compute_returns(obs)

    def freeze_actor(self, updates: int) -> None:
        """Fit the critic alone in the next ``updates`` calls of :meth:`update`, at a fixed
        learning rate: a warm-started actor is not moved by the advantages of an untrained
        critic, and the KL-adaptive learning rate does not climb while the actor's KL is zero."""
        self.frozen_updates = int(updates)

    def update(self) -> dict[str, float]:
        """PPO's update, or the critic's alone while the actor is frozen (:meth:`freeze_actor`)."""
        with self.learning_threads():
            return self._update()

    def anchor_actor(self, pull: float, weights: list[torch.Tensor] | None = None) -> None:
        """Pull the actor back towards ``weights`` (default: its present ones, the warm start)
        by the fraction ``pull`` after every PPO update: ``theta <- theta + pull (theta_0 - theta)``,
        weight decay towards the prior rather than towards 0. PPO's drift on a noisy reward
        decays with a half-life of about ln 2 / pull iterations; a push the reward keeps up
        holds. 0: no anchor."""
        if not 0.0 <= pull < 1.0:
            raise ValueError(f"prior pull must be in [0, 1), got {pull}")
        self.prior_pull = float(pull)
        src = list(self.actor.parameters()) if weights is None else weights
        self.anchor = [w.detach().clone() for w in src] if pull > 0 else None

    def _pull_to_anchor(self) -> None:
        if self.anchor is None:
            return
        with torch.no_grad():
            for p, p0 in zip(self.actor.parameters(), self.anchor):
                p.lerp_(p0.to(p.device), self.prior_pull)

    def _update(self) -> dict[str, float]:
        if self.frozen_updates <= 0:
            losses = super().update()
            self._pull_to_anchor()
            return losses
        self.frozen_updates -= 1
        params = list(self.actor.parameters())
        trainable = [p.requires_grad for p in params]
        schedule, lr, normalize = self.schedule, self.learning_rate, self.actor.obs_normalization
        for p in params:
            p.requires_grad_(False)      # no gradient: Adam leaves them (and their moments) alone
        self.schedule = "fixed"
        self.actor.obs_normalization = False   # its input statistics stay too: the same function
        try:
            return super().update()
        finally:
            for p, t in zip(params, trainable):
                p.requires_grad_(t)
            self.schedule, self.learning_rate, self.actor.obs_normalization = schedule, lr, normalize

    def fix_actor_normalizer(self) -> None:
        """Stop updating the actor's observation normaliser (its statistics stay as they are):
        a warm-started actor was fitted with the statistics of its teacher's data, and running
        statistics of PPO's rollouts would change what it computes."""
        self.actor.obs_normalization = False
