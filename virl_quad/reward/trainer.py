"""Optimisation of a reward network: Adam, gradient-norm clipping, private RNGs, checkpointable state.

The trainer owns its randomness: a numpy Generator for batch drawing and a
private torch CPU RNG state for dropout and VAE sampling, swapped in only
while :meth:`Trainer.update` runs. A seeded run therefore gives the same
losses and weights whatever the caller does with the global RNGs (on CPU; on
a GPU, dropout draws from the device RNG, which is not isolated).
"""

from __future__ import annotations

import json
from typing import Callable

import numpy as np
import torch
from torch import nn

#: A function drawing one batch with the given numpy RNG and returning (loss, logs).
LossFn = Callable[[np.random.Generator], tuple[torch.Tensor, dict[str, float]]]


class Trainer:
    """M batch updates of ``module`` per call, with Adam(lr) and global gradient-norm clipping."""

    def __init__(self, module: nn.Module, loss_fn: LossFn, lr: float, grad_clip: float, seed: int) -> None:
        self.module, self.loss_fn, self.grad_clip = module, loss_fn, float(grad_clip)
        self.params = [p for p in module.parameters() if p.requires_grad]
        self.opt = torch.optim.Adam(self.params, lr=lr)
        self.rng = np.random.default_rng(seed)
        gen = torch.Generator().manual_seed(int(seed) + 1)
        self._torch_rng = gen.get_state()
        self.num_updates = 0

    def update(self, num_updates: int) -> dict[str, float]:
        """Run ``num_updates`` batch updates; return the mean of each logged loss and of the gradient norm.

        The module is left in eval mode (the mode rewards are computed in).
        """
        if num_updates < 0:
            raise ValueError(f"num_updates must be >= 0, got {num_updates}")
        sums: dict[str, float] = {}
        with torch.random.fork_rng(devices=[]):
            torch.set_rng_state(self._torch_rng)
            self.module.train()
            try:
                for _ in range(num_updates):
                    loss, logs = self.loss_fn(self.rng)
                    self.opt.zero_grad(set_to_none=True)
                    loss.backward()
                    gnorm = torch.nn.utils.clip_grad_norm_(self.params, self.grad_clip)
                    self.opt.step()
                    self.num_updates += 1
                    logs = dict(logs, grad_norm=float(gnorm))
                    for k, v in logs.items():
                        sums[k] = sums.get(k, 0.0) + v
            finally:
                self.module.eval()
                self._torch_rng = torch.get_rng_state()
        return {k: v / num_updates for k, v in sums.items()} if num_updates else {}

    def state_dict(self) -> dict:
        """Optimiser state, both RNG states and the update count (weights_only-loadable types)."""
        return {
            "optimizer": self.opt.state_dict(),
            "numpy_rng": json.dumps(self.rng.bit_generator.state),
            "torch_rng": self._torch_rng.clone(),
            "num_updates": self.num_updates,
        }

    def load_state_dict(self, d: dict) -> None:
        """Restore what :meth:`state_dict` saved."""
        self.opt.load_state_dict(d["optimizer"])
        self.rng.bit_generator.state = json.loads(d["numpy_rng"])
        self._torch_rng = d["torch_rng"].clone()
        self.num_updates = int(d["num_updates"])
