"""Configuration of the learned video distance and its reward (VIRL, Berseth et al. 2023).

Numbers marked "paper" come from /work/shared/VIRL.md; the others are this
project's choices (the paper gives no figure) and say so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any

VARIANTS: tuple[str, ...] = ("virl", "frame", "sequence", "no_ae", "gaifo")

POSITIVE_PAIRS: tuple[str, ...] = ("gaussian_noise", "out_of_sync", "duplicate_first",
                                   "duplicate_last", "same_source")
NEGATIVE_PAIRS: tuple[str, ...] = ("reversed", "frozen_frame", "shuffled_one", "shuffled_both",
                                   "expert_vs_agent", "other_clip")
#: Settings of retired features (the speed strip and its speed_shift negatives; the ground_shift
#: positives, identical to the demonstration once its background is painted) that configs saved
#: by older versions hold: reading such a config drops them (:func:`without_retired`), so their
#: models still load.
RETIRED_FIELDS: tuple[str, ...] = ("speed_strip",)
RETIRED_PAIRS: tuple[str, ...] = ("speed_shift", "ground_shift")


@dataclass
class RewardConfig:
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

    # -- frames ---------------------------------------------------------------------------
    image_size: int = 48              # px, square grayscale frames (paper: 48x48)

    # -- frame encoder phi / decoder psi (paper sizes) -------------------------------------
    conv1_filters: int = 8            # paper: 8 filters 6x6 stride 2
    conv1_kernel: int = 6             # px
    conv1_stride: int = 2
    conv2_filters: int = 16           # paper: 16 filters 4x4 stride 2
    conv2_kernel: int = 4             # px
    conv2_stride: int = 2
    dense_units: int = 256            # paper: dense 256
    frame_latent: int = 64            # paper: dense 64 (sigmoid) = e_t
    dropout: float = 0.1              # probability of dropping a whole conv1 feature map
                                      # (Dropout2d, between the conv layers; project choice)

    # -- sequence encoder omega / decoder rho (paper sizes) --------------------------------
    lstm_units: int = 128             # paper: LSTM 128 units
    seq_latent: int = 64              # paper: dense 64 = h_t
    decoder_lstm_units: int = 128     # decoder LSTM size (project choice: mirror of the encoder)

    # -- losses (paper weights 0.7 / 0.1 / 0.1 / 0.1, margin 1) ----------------------------
    w_sns: float = 0.7                # contrastive loss on sequence encodings h
    w_sni: float = 0.1                # contrastive loss on frame encodings e, mean over time
    w_raes: float = 0.1               # sequence autoencoder L2 (reversed-order decoding)
    w_vaei: float = 0.1               # per-frame VAE loss (reconstruction + KL)
    margin: float = 1.0               # contrastive margin on the SQUARED distance
    vae_beta: float = 1e-3            # KL weight inside L_VAEI; reconstruction is a per-pixel
                                      # mean, KL a sum over latent dims (project choice)

    w_gp: float = 0.0                 # gradient penalty: the squared input gradient of the pair
                                      # distance (losses.gradient_penalty); 0: off, as in the paper
    ae_frames: int = 128              # frames decoded per update for each of L_RAES and L_VAEI: a
                                      # random subset (unbiased for the mean); 0 = all (CPU cost)

    # -- pairs and augmentation --------------------------------------------------------------
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
                                      # places, and say nothing about the legs (project choice)
    clips_cyclic: bool = False        # the demonstration and other clips loop: windows cut from
                                      # them wrap around their end (else they must fit inside)
    warp_min: float = 0.5             # paper: demonstration replay speed range [0.5, 2.0]
    warp_max: float = 2.0             # (sampled log-uniformly, project choice)

    # -- optimiser (released code: Adam 1e-3, clip 1.0) -------------------------------------
    lr: float = 1e-3                  # Adam learning rate
    grad_clip: float = 1.0            # max global gradient L2 norm
    ema: float = 0.99                 # rewards come from a slowly moving copy of the model, moved
                                      # this much less than all the way to the trained weights after
                                      # every update (0: from the trained model itself, as in the
                                      # paper); smooths the reward a policy climbs (project choice)

    # -- reward -----------------------------------------------------------------------------
    w_d: float = -5.0                 # paper: r = exp(w_d * d^2)
    reward_floor: float = 1e-8        # r is clamped to >= this so float underflow never gives 0

    # -- off-policy dataset -----------------------------------------------------------------
    max_bytes: int = 256 * 2**20      # bytes of frames kept (agent + expert), oldest evicted
    max_episode_frames: int = 512     # frames; longer episodes are stored as pieces this long

    def validate(self) -> "RewardConfig":
        """Raise ValueError (one line) on an inconsistent setting; return self."""
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown variant {self.variant!r}; choose one of: {', '.join(VARIANTS)}")
        if self.image_size != 48:
            raise ValueError(f"image_size must be 48 (the paper's frame size), got {self.image_size}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        if self.batch_pairs < 2 or self.batch_pairs % 2:
            raise ValueError(f"batch_pairs must be even and >= 2, got {self.batch_pairs}")
        if not 2 <= self.window_min <= self.window_max:
            raise ValueError(f"need 2 <= window_min <= window_max, got {self.window_min}, {self.window_max}")
        if not 0.0 < self.warp_min <= 1.0 <= self.warp_max:
            raise ValueError(f"need 0 < warp_min <= 1 <= warp_max, got {self.warp_min}, {self.warp_max}")
        if self.w_d >= 0:
            raise ValueError(f"w_d must be negative so the reward falls with distance, got {self.w_d}")
        if not 0.0 < self.reward_floor < 1.0:
            raise ValueError(f"reward_floor must be in (0, 1), got {self.reward_floor}")
        if self.margin <= 0 or self.lr <= 0 or self.grad_clip <= 0:
            raise ValueError("margin, lr and grad_clip must be positive")
        if not 0.0 <= self.ema < 1.0:
            raise ValueError(f"ema must be in [0, 1), got {self.ema}")
        if self.w_gp < 0:
            raise ValueError(f"w_gp must be >= 0, got {self.w_gp}")
        if self.ae_frames < 0:
            raise ValueError(f"ae_frames must be >= 0, got {self.ae_frames}")
        if self.max_bytes <= 0 or self.max_episode_frames < 2:
            raise ValueError("max_bytes must be positive and max_episode_frames >= 2")
        unknown = set(self.pair_weights) - set(POSITIVE_PAIRS) - set(NEGATIVE_PAIRS)
        if unknown:
            raise ValueError(f"unknown pair constructors in pair_weights: {sorted(unknown)}")
        if any(w < 0 for w in self.pair_weights.values()):
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
        """Plain dict (str/int/float/dict) for saving with weights_only torch files."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "RewardConfig":
        """Inverse of :meth:`to_dict` (settings of retired features dropped, see
        :func:`without_retired`); other unknown keys raise ValueError."""
        d = without_retired(d)
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown RewardConfig fields: {sorted(unknown)}")
        return cls(**d).validate()


def without_retired(d: dict[str, Any]) -> dict[str, Any]:
    """A copy of the saved RewardConfig dict ``d`` without the settings of retired features
    (:data:`RETIRED_FIELDS`, and :data:`RETIRED_PAIRS` in its ``pair_weights``): how a config
    saved by an older version compares with, and loads as, today's (settings added since take
    the value that reproduces the old behaviour)."""
    out = {k: v for k, v in d.items() if k not in RETIRED_FIELDS}
    out.setdefault("paint_background", False)        # saved before backgrounds were painted
    out.setdefault("ema", 0.0)                       # saved before rewards came from a slow copy
    out.setdefault("w_gp", 0.0)                      # saved before the gradient penalty existed
    if isinstance(out.get("pair_weights"), dict):
        out["pair_weights"] = {k: v for k, v in out["pair_weights"].items() if k not in RETIRED_PAIRS}
    return out
