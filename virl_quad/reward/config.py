"""Configuration of the learned video distance and its reward (VIRL, Berseth et al. 2023).

Numbers marked "paper" come from /work/shared/VIRL.md; the others are this
project's choices (the paper gives no figure) and say so.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

from virl_quad.cli import Sectioned, from_options, options

VARIANTS: tuple[str, ...] = ("virl", "frame", "sequence", "no_ae", "gaifo")

POSITIVE_PAIRS: tuple[str, ...] = ("gaussian_noise", "out_of_sync", "duplicate_first",
                                   "duplicate_last", "same_source")
NEGATIVE_PAIRS: tuple[str, ...] = ("reversed", "frozen_frame", "shuffled_one", "shuffled_both",
                                   "expert_vs_agent", "other_clip")
#: Settings of retired features (the speed strip and its speed_shift negatives; the ground_shift
#: positives, identical to the demonstration once its background is painted; the gradient
#: penalty, which flattened the reward) that configs saved
#: by older versions hold: reading such a config drops them (:func:`without_retired`), so their
#: models still load.
RETIRED_FIELDS: tuple[str, ...] = ("speed_strip", "w_gp")
RETIRED_PAIRS: tuple[str, ...] = ("speed_shift", "ground_shift")


@dataclass
class ArchitectureConfig:
    """The networks: frame encoder phi / decoder psi, sequence encoder omega / decoder rho (paper sizes)."""

    image_size: int = 48              # px, square grayscale frames (paper: 48x48)
    conv1_filters: int = 8            # paper: 8 filters 6x6 stride 2
    conv1_kernel: int = 6             # px
    conv1_stride: int = 2
    conv2_filters: int = 16           # paper: 16 filters 4x4 stride 2
    conv2_kernel: int = 4             # px
    conv2_stride: int = 2
    dense_units: int = 256            # paper: dense 256
    frame_latent: int = 64            # paper: dense 64 (sigmoid) = e_t
    dropout: float = 0.1              # probability of dropping a unit of phi's conv1 output (between
                                      # the conv layers, paper; rate: project choice). Per unit, not
                                      # whole feature maps: with 8 maps a dropped map can move the
                                      # encoding more than any frame does, the batch-norm statistics
                                      # then hold that spread, and clean frames (the reward's) all map
                                      # alike. (GAIfO's discriminator, with no batch norm, drops maps)
    latent_norm: bool = True          # batch-normalise e's pre-activation before its sigmoid (project
                                      # choice): a fresh encoder maps the mostly-white frames almost
                                      # alike (spread of e ~1e-3) and can stay there, its sigmoid
                                      # saturated, every behaviour then rewarded 1; normalised, e
                                      # spreads from the first updates
    latent_norm_eps: float = 1e-12    # the batch norm's variance floor: far below the frames' own
                                      # variance of that pre-activation (1e-9 .. 1e-4), so the encoding
                                      # never depends on its scale (torch's 1e-5 does at these
                                      # spreads: shrinking every pre-activation then draws positive
                                      # pairs together, and the encoder can sink to one point, where
                                      # the contrastive loss has no gradient left)
    lstm_units: int = 128             # paper: LSTM 128 units
    seq_latent: int = 64              # paper: dense 64 = h_t
    decoder_lstm_units: int = 128     # decoder LSTM size (project choice: mirror of the encoder)


@dataclass
class LossConfig:
    """The four VIRL losses (paper weights 0.7 / 0.1 / 0.1 / 0.1, margin 1)."""

    w_sns: float = 0.7                # contrastive loss on sequence encodings h
    w_sni: float = 0.1                # contrastive loss on frame encodings e, mean over time
    w_raes: float = 0.1               # sequence autoencoder L2 (reversed-order decoding)
    w_vaei: float = 0.1               # per-frame VAE loss (reconstruction + KL)
    margin: float = 1.0               # contrastive margin on the SQUARED distance
    vae_beta: float = 1e-5            # KL weight inside L_VAEI; reconstruction is a per-pixel
                                      # mean, KL a sum over latent dims (project choice): about
                                      # 0.02 of a standard VAE's (pixel-sum) KL weight. The KL pulls
                                      # the sigmoid mean e towards 0; stronger, that pull can
                                      # saturate every unit, the encoder then maps every frame to
                                      # the same e and every behaviour gets reward 1
    ae_frames: int = 128              # frames decoded per update for each of L_RAES and L_VAEI: a
                                      # random subset (unbiased for the mean); 0 = all (CPU cost)


@dataclass
class PairConfig:
    """The training pairs: how windows are cut, augmented and paired."""

    batch_pairs: int = 16             # pairs per update: half positive, half negative
                                      # (= 2 * batch_pairs sequences through the model)
    noise_sigma: float = 0.05         # paper: Gaussian noise std on frames scaled to [0, 1]
    same_source_max_offset: int = 3   # frames; max start offset of two same-source windows
                                      # (project choice; keeps frames roughly aligned)
    agent_source_prob: float = 0.5    # P(anchor material is an agent window | agent data exists)
    pair_weights: dict[str, float] = field(default_factory=dict)  # constructor name -> relative
                                      # sampling weight; missing names weigh 1, 0 disables one
    window_min: int = 8               # frames, shortest training window (project choice)
    window_max: int = 64              # frames, longest window; EESP caps it further at the
                                      # current mean episode length (project choice: CPU cost)
    paint_background: bool = True     # every frame the model sees has the demonstration's flat
                                      # background (the gray levels of its border rows: sky and
                                      # ground) painted white: the ground's scroll and pattern phase
                                      # differ whenever agent and demonstration stand at different
                                      # places, and say nothing about the legs; on a textured ground
                                      # every level from the ground's darkest up (frames.painted_levels)
                                      # (project choice)
    clips_cyclic: bool = False        # the demonstration and other clips loop: windows cut from
                                      # them wrap around their end (else they must fit inside)
    view_zoom: float = 0.05           # every window of every pair is seen through its own camera
                                      # move: zoomed by up to this fraction (log-uniform) and shifted
    view_shift: float = 2.0           # by up to this many px vertically, half as many horizontally
                                      # (project choice, the size of the agent camera's per-episode
                                      # jitter, distance and height +-5 %): only agent frames vary
                                      # their viewpoint, and a model that reads it ranks behaviours
                                      # by the camera draw instead of the motion. 0 and 0: off
    warp_min: float = 0.5             # paper: demonstration replay speed range [0.5, 2.0]
    warp_max: float = 2.0             # (sampled log-uniformly, project choice)


@dataclass
class OptimConfig:
    """The optimiser (released code: Adam 1e-3, clip 1.0) and the reward copy."""

    lr: float = 1e-3                  # Adam learning rate
    grad_clip: float = 1.0            # max global gradient L2 norm
    ema: float = 0.99                 # rewards come from a slowly moving copy of the model, moved
                                      # this much less than all the way to the trained weights after
                                      # every update (0: from the trained model itself, as in the
                                      # paper); smooths the reward a policy climbs (project choice)


@dataclass
class RewardShapeConfig:
    """From distance to reward."""

    w_d: float = -5.0                 # paper: r = exp(w_d * d^2)
    reward_floor: float = 1e-8        # r is clamped to >= this so float underflow never gives 0
    calibrate: bool = True            # d^2 counted in units of the model's own mean d^2 between the
                                      # demonstration and its negatives (the other clips; without
                                      # clips, the demonstration reversed), measured after every
                                      # update: the contrastive margin pushes every non-positive
                                      # pair ever further apart as training goes on, and exp(w_d d^2)
                                      # of raw distances sinks to 0 for every agent behaviour while
                                      # the model still ranks them; so calibrated, a behaviour as
                                      # far from the demonstration as another gait gets exp(w_d)
                                      # (project choice; not for gaifo)


@dataclass
class StoreConfig:
    """The off-policy dataset of agent and expert frames."""

    max_bytes: int = 256 * 2**20      # bytes of frames kept (agent + expert), oldest evicted
    max_episode_frames: int = 512     # frames; longer episodes are stored as pieces this long


@dataclass
class RewardConfig(Sectioned):
    """Everything that shapes the distance model, its training and the reward.

    ``variant`` picks the method or a baseline/ablation:

    - ``"virl"``: the paper's model; reward from the sequence + frame terms.
    - ``"frame"``: TCN-like baseline; frame encoder only (no LSTMs), reward from
      the frame term; trained with the frame contrastive loss (weight
      ``w_sns + w_sni``) and the per-frame VAE loss.
    - ``"sequence"``: the full model and losses, reward from the sequence term only.
    - ``"no_ae"``: the full distance, trained without L_RAES and L_VAEI (no decoders).
    - ``"gaifo"``: GAIfO baseline; a discriminator on consecutive frame pairs
      (expert = 1, agent = 0); reward r = D(o_{t-1}, o_t) in (0, 1].
    """

    variant: str = "virl"
    arch: ArchitectureConfig
    loss: LossConfig
    pairs: PairConfig
    optim: OptimConfig
    reward: RewardShapeConfig
    store: StoreConfig

    def validate(self) -> "RewardConfig":
        """Raise ValueError (one line) on an inconsistent setting; return self."""
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown variant {self.variant!r}; choose one of: {', '.join(VARIANTS)}")
        if self.arch.image_size != 48:
            raise ValueError(f"image_size must be 48 (the paper's frame size), got {self.arch.image_size}")
        if self.arch.latent_norm_eps <= 0:
            raise ValueError(f"latent_norm_eps must be positive, got {self.arch.latent_norm_eps}")
        if not 0.0 <= self.arch.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {self.arch.dropout}")
        if not 0.0 <= self.pairs.view_zoom < 0.5 or self.pairs.view_shift < 0:
            raise ValueError(f"view_zoom must be in [0, 0.5) and view_shift >= 0, got {self.pairs.view_zoom}, "
                             f"{self.pairs.view_shift}")
        if self.pairs.batch_pairs < 2 or self.pairs.batch_pairs % 2:
            raise ValueError(f"batch_pairs must be even and >= 2, got {self.pairs.batch_pairs}")
        if not 2 <= self.pairs.window_min <= self.pairs.window_max:
            raise ValueError(f"need 2 <= window_min <= window_max, got {self.pairs.window_min}, "
                             f"{self.pairs.window_max}")
        if not 0.0 < self.pairs.warp_min <= 1.0 <= self.pairs.warp_max:
            raise ValueError(f"need 0 < warp_min <= 1 <= warp_max, got {self.pairs.warp_min}, {self.pairs.warp_max}")
        if self.reward.w_d >= 0:
            raise ValueError(f"w_d must be negative so the reward falls with distance, got {self.reward.w_d}")
        if not 0.0 < self.reward.reward_floor < 1.0:
            raise ValueError(f"reward_floor must be in (0, 1), got {self.reward.reward_floor}")
        if self.loss.margin <= 0 or self.optim.lr <= 0 or self.optim.grad_clip <= 0:
            raise ValueError("margin, lr and grad_clip must be positive")
        if not 0.0 <= self.optim.ema < 1.0:
            raise ValueError(f"ema must be in [0, 1), got {self.optim.ema}")
        if self.loss.ae_frames < 0:
            raise ValueError(f"ae_frames must be >= 0, got {self.loss.ae_frames}")
        if self.store.max_bytes <= 0 or self.store.max_episode_frames < 2:
            raise ValueError("max_bytes must be positive and max_episode_frames >= 2")
        unknown = set(self.pairs.pair_weights) - set(POSITIVE_PAIRS) - set(NEGATIVE_PAIRS)
        if unknown:
            raise ValueError(f"unknown pair constructors in pair_weights: {sorted(unknown)}")
        if any(w < 0 for w in self.pairs.pair_weights.values()):
            raise ValueError("pair_weights must be >= 0")
        return self

    @property
    def uses_lstm(self) -> bool:
        """Whether the model has the sequence encoder (all variants but frame and gaifo)."""
        return self.variant in ("virl", "sequence", "no_ae")

    @property
    def uses_decoders(self) -> bool:
        """Whether the autoencoder losses (and decoder modules) are used."""
        return self.variant in ("virl", "sequence", "frame")

    def to_dict(self) -> dict[str, Any]:
        """One flat ``{setting: value}`` dict (names are unique across sections; str/int/float/dict)
        for saving with weights_only torch files."""
        return copy.deepcopy(options(self))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "RewardConfig":
        """Inverse of :meth:`to_dict` (settings of retired features dropped, see
        :func:`without_retired`); other unknown keys raise ValueError."""
        d = without_retired(d)
        unknown = set(d) - set(options(cls()))
        if unknown:
            raise ValueError(f"unknown RewardConfig fields: {sorted(unknown)}")
        return from_options(cls, d).validate()


def without_retired(d: dict[str, Any]) -> dict[str, Any]:
    """A copy of the saved RewardConfig dict ``d`` without the settings of retired features
    (:data:`RETIRED_FIELDS`, and :data:`RETIRED_PAIRS` in its ``pair_weights``): how a config
    saved by an older version compares with, and loads as, today's (settings added since take
    the value that reproduces the old behaviour)."""
    out = {k: v for k, v in d.items() if k not in RETIRED_FIELDS}
    out.setdefault("paint_background", False)        # saved before backgrounds were painted
    out.setdefault("ema", 0.0)                       # saved before rewards came from a slow copy
    out.setdefault("latent_norm", False)             # saved before e was normalised
    out.setdefault("latent_norm_eps", 1e-5)          # saved with torch's default variance floor
    out.setdefault("calibrate", False)               # saved before d^2 was calibrated
    out.setdefault("view_zoom", 0.0)                 # saved before windows were seen through
    out.setdefault("view_shift", 0.0)                # a moved camera
    if isinstance(out.get("pair_weights"), dict):
        out["pair_weights"] = {k: v for k, v in out["pair_weights"].items() if k not in RETIRED_PAIRS}
    return out
