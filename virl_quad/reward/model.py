"""The Siamese distance network: frame VAE (phi, psi) and sequence LSTM autoencoder (omega, rho).

All sequence tensors are time-major: frames [T, B, 48, 48] float in [0, 1],
frame encodings e [T, B, frame_latent], sequence encodings h [T, B, seq_latent].
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from virl_quad.reward.config import RewardConfig


def conv_out(size: int, kernel: int, stride: int) -> int:
    """Output side of a 'valid' convolution."""
    return (size - kernel) // stride + 1


class FrameEncoder(nn.Module):
    """phi: conv 8@6x6/2 -> dropout -> conv 16@4x4/2 -> dense 256 -> dense 64 (batch norm with
    ``latent_norm``, sigmoid) = mu; log-variance head."""

    def __init__(self, cfg: RewardConfig) -> None:
        super().__init__()
        a = cfg.arch
        self.size = a.image_size
        self.conv1 = nn.Conv2d(1, a.conv1_filters, a.conv1_kernel, a.conv1_stride)
        self.drop = nn.Dropout(a.dropout)    # per unit, not whole maps: see ArchitectureConfig.dropout
        self.conv2 = nn.Conv2d(a.conv1_filters, a.conv2_filters, a.conv2_kernel, a.conv2_stride)
        n1 = conv_out(a.image_size, a.conv1_kernel, a.conv1_stride)
        n2 = conv_out(n1, a.conv2_kernel, a.conv2_stride)
        self.grid = (a.conv2_filters, n2, n2)
        self.fc = nn.Linear(a.conv2_filters * n2 * n2, a.dense_units)
        self.mu = nn.Linear(a.dense_units, a.frame_latent)
        self.logvar = nn.Linear(a.dense_units, a.frame_latent)
        self.norm = nn.BatchNorm1d(a.frame_latent, eps=a.latent_norm_eps) if a.latent_norm else nn.Identity()

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames [..., H, W] in [0, 1] -> (mu, logvar), each [..., frame_latent]; mu in (0, 1)."""
        lead = x.shape[:-2]
        z = x.reshape(-1, 1, self.size, self.size)
        z = self.drop(F.relu(self.conv1(z)))
        z = F.relu(self.conv2(z))
        z = F.relu(self.fc(z.flatten(1)))
        mu = torch.sigmoid(self.norm(self.mu(z)))
        logvar = self.logvar(z).clamp(-12.0, 6.0)
        return mu.reshape(*lead, -1), logvar.reshape(*lead, -1)


class ConvTranspose2d(nn.ConvTranspose2d):
    """A transposed convolution computed, when the kernel is a multiple of the stride, as one ordinary
    convolution with s*s sub-kernels followed by a pixel shuffle ("sub-pixel" form).

    The result equals ``nn.ConvTranspose2d`` (same weight layout and output size) up to float rounding;
    it is several times faster on CPU for these small channel counts. Other shapes use the stock op.
    """

    def forward(self, x: torch.Tensor, output_size=None) -> torch.Tensor:
        """Transposed convolution of x [B, Cin, H, W]."""
        s, k = self.stride[0], self.kernel_size[0]
        plain = (self.stride[1] == s and self.kernel_size[1] == k and k % s == 0 and self.padding == (0, 0)
                 and self.output_padding == (0, 0) and self.dilation == (1, 1) and self.groups == 1)
        if not plain or output_size is not None:
            return super().forward(x, output_size)
        cin, cout, kk = self.in_channels, self.out_channels, k // s
        # weight[cin, cout, s*j + p, s*l + q] -> kernel[cout*s*s + p*s + q, cin, kk-1-j, kk-1-l]
        w = self.weight.reshape(cin, cout, kk, s, kk, s).flip(2, 4)
        w = w.permute(1, 3, 5, 0, 2, 4).reshape(cout * s * s, cin, kk, kk)
        b = None if self.bias is None else self.bias.repeat_interleave(s * s)
        return F.pixel_shuffle(F.conv2d(x, w, b, padding=kk - 1), s)


class FrameDecoder(nn.Module):
    """psi: the mirror of phi with transposed convolutions; latent [..., 64] -> frames [..., 48, 48] in (0, 1)."""

    def __init__(self, cfg: RewardConfig, grid: tuple[int, int, int]) -> None:
        super().__init__()
        a = cfg.arch
        self.size, self.grid = a.image_size, grid
        c2, n2, _ = grid
        self.fc1 = nn.Linear(a.frame_latent, a.dense_units)
        self.fc2 = nn.Linear(a.dense_units, c2 * n2 * n2)
        n1 = conv_out(a.image_size, a.conv1_kernel, a.conv1_stride)
        pad2 = n1 - ((n2 - 1) * a.conv2_stride + a.conv2_kernel)
        pad1 = a.image_size - ((n1 - 1) * a.conv1_stride + a.conv1_kernel)
        self.deconv2 = ConvTranspose2d(c2, a.conv1_filters, a.conv2_kernel, a.conv2_stride, output_padding=pad2)
        self.deconv1 = ConvTranspose2d(a.conv1_filters, 1, a.conv1_kernel, a.conv1_stride, output_padding=pad1)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Latent [..., frame_latent] -> frames [..., H, W] in (0, 1)."""
        lead = z.shape[:-1]
        x = F.relu(self.fc1(z.reshape(-1, z.shape[-1])))
        x = F.relu(self.fc2(x)).reshape(-1, *self.grid)
        x = F.relu(self.deconv2(x))
        x = torch.sigmoid(self.deconv1(x))
        return x.reshape(*lead, self.size, self.size)


class SequenceEncoder(nn.Module):
    """omega: LSTM over e_0..e_t, then dense -> h_t."""

    def __init__(self, cfg: RewardConfig) -> None:
        super().__init__()
        a = cfg.arch
        self.lstm = nn.LSTM(a.frame_latent, a.lstm_units)
        self.head = nn.Linear(a.lstm_units, a.seq_latent)

    def forward(self, e: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None
                ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """e [T, B, frame_latent] (+ optional LSTM (h, c), each [1, B, units]) -> (h [T, B, seq_latent], state)."""
        out, state = self.lstm(e, state)
        return self.head(out), state


class SequenceDecoder(nn.Module):
    """rho: an LSTM fed h at every step that emits latent frames y_0..y_{T-1} in REVERSE order.

    y_k is the latent of frame T-1-k: the last frame comes out first.
    """

    def __init__(self, cfg: RewardConfig) -> None:
        super().__init__()
        a = cfg.arch
        self.lstm = nn.LSTM(a.seq_latent, a.decoder_lstm_units)
        self.head = nn.Linear(a.decoder_lstm_units, a.frame_latent)

    def forward(self, h: torch.Tensor, length: int) -> torch.Tensor:
        """h [B, seq_latent] -> reversed latent frames [length, B, frame_latent] in (0, 1)."""
        out, _ = self.lstm(h.unsqueeze(0).expand(length, *h.shape))
        return torch.sigmoid(self.head(out))


class DistanceModel(nn.Module):
    """Everything the VIRL distance needs; parts a variant does not use are not built."""

    def __init__(self, cfg: RewardConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.phi = FrameEncoder(cfg)
        self.psi = FrameDecoder(cfg, self.phi.grid) if cfg.uses_decoders else None
        self.omega = SequenceEncoder(cfg) if cfg.uses_lstm else None
        self.rho = SequenceDecoder(cfg) if (cfg.uses_lstm and cfg.uses_decoders) else None

    def encode_frames(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames [..., H, W] -> (mu = e, logvar), each [..., frame_latent]."""
        return self.phi(x)

    def encode_sequence(self, e: torch.Tensor, state=None):
        """Frame encodings [T, B, frame_latent] -> (h [T, B, seq_latent], LSTM state)."""
        if self.omega is None:
            raise ValueError(f"variant {self.cfg.variant!r} has no sequence encoder")
        return self.omega(e, state)

    def decode_sequence_reversed(self, h_last: torch.Tensor, length: int) -> torch.Tensor:
        """h of the whole sequence [B, seq_latent] -> decoded frames [length, B, H, W], LAST frame first."""
        if self.rho is None or self.psi is None:
            raise ValueError(f"variant {self.cfg.variant!r} has no sequence decoder")
        return self.psi(self.rho(h_last, length))

    @torch.no_grad()
    def reconstruct_sequence(self, x: torch.Tensor) -> torch.Tensor:
        """Autoencode frames [T, B, H, W]; return the reconstruction put back in forward time order."""
        mu, _ = self.encode_frames(x)
        h, _ = self.encode_sequence(mu)
        return self.decode_sequence_reversed(h[-1], x.shape[0]).flip(0)
