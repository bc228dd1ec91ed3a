"""Off-policy store of agent episodes: agent frames with their matching expert frames, as uint8.

Memory is bounded in bytes (frame payload: agent + expert images, including
the per-env buffers of episodes still open in :meth:`EpisodeStore.add_rollout`);
the oldest finished episodes are evicted first.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from virl_quad.reward.frames import FRAME, to_mask, to_uint8


class EpisodeStore:
    """A FIFO of (agent [T, 48, 48] uint8, expert [T, 48, 48] uint8) episodes under a byte budget."""

    def __init__(self, max_bytes: int, max_episode_frames: int = 512) -> None:
        if max_bytes <= 0 or max_episode_frames < 2:
            raise ValueError("max_bytes must be positive and max_episode_frames >= 2")
        self.max_bytes = int(max_bytes)
        self.max_episode_frames = int(max_episode_frames)
        self._episodes: deque[tuple[np.ndarray, np.ndarray]] = deque()
        self._stored_bytes = 0
        self._open: dict[int, tuple[np.ndarray, np.ndarray, int]] = {}  # env -> (agent, expert buffers, used)
        self._open_bytes = 0
        self.episodes_added = 0
        self.episodes_evicted = 0

    # -- adding -----------------------------------------------------------------------------
    def add_episode(self, agent, expert) -> None:
        """Store one episode: agent and expert frames [T, 48, 48] (uint8, or float in [0, 1]), same T >= 1."""
        a = to_uint8(agent, "agent_frames", "T")
        e = to_uint8(expert, "expert_frames", "T")
        if a.shape != e.shape:
            raise ValueError(f"agent and expert frames differ in shape: {list(a.shape)} vs {list(e.shape)}")
        for s in range(0, a.shape[0], self.max_episode_frames):
            self._push(a[s:s + self.max_episode_frames], e[s:s + self.max_episode_frames])

    def add_rollout(self, agent, expert, dones) -> int:
        """Add a rollout [T, N, 48, 48] of N envs; ``dones`` [T, N]: frame t is the last of its episode.

        Frames of an episode still running at the end of the rollout stay in a
        per-env open buffer, joined with the next rollout's frames of the same env
        (the env count must stay the same); open episodes can already be sampled
        (:meth:`sequences`). Pieces reaching ``max_episode_frames`` are stored as
        separate episodes. Returns the number of episodes finished by this call.
        """
        a = to_uint8(agent, "agent_frames", "TN")
        e = to_uint8(expert, "expert_frames", "TN")
        if a.shape != e.shape:
            raise ValueError(f"agent and expert frames differ in shape: {list(a.shape)} vs {list(e.shape)}")
        T, N = a.shape[:2]
        d = to_mask(dones, "dones", (T, N)).numpy()
        if self._open and max(self._open) >= N:
            raise ValueError(f"rollout has {N} envs but earlier rollouts had more")
        before = self.episodes_added
        for n in range(N):  # storage bookkeeping only; the reward path has no loop over envs
            start = 0
            for t in np.flatnonzero(d[:, n]).tolist() + [None]:
                stop = T if t is None else t + 1
                for s in range(start, stop, self.max_episode_frames):
                    self._append_open(n, a[s:min(stop, s + self.max_episode_frames), n],
                                      e[s:min(stop, s + self.max_episode_frames), n])
                if t is not None:
                    self._close(n)
                start = stop
        self._evict()
        return self.episodes_added - before

    def flush(self) -> None:
        """Store the open episodes of every env as finished episodes."""
        for n in list(self._open):
            self._close(n)

    def _append_open(self, n: int, a: np.ndarray, e: np.ndarray) -> None:
        """Append frames to env n's open buffer (amortised growth, capped at max_episode_frames)."""
        k = a.shape[0]
        buf_a, buf_e, used = self._open.get(n, (None, None, 0))
        if used + k > self.max_episode_frames:
            self._close(n)
            buf_a, buf_e, used = None, None, 0
        cap = 0 if buf_a is None else buf_a.shape[0]
        if used + k > cap:
            new_cap = min(self.max_episode_frames, max(2 * cap, used + k, 32))
            grown_a = np.empty((new_cap, FRAME, FRAME), np.uint8)
            grown_e = np.empty((new_cap, FRAME, FRAME), np.uint8)
            if used:
                grown_a[:used], grown_e[:used] = buf_a[:used], buf_e[:used]
            self._open_bytes += (new_cap - cap) * 2 * FRAME * FRAME
            buf_a, buf_e = grown_a, grown_e
        buf_a[used:used + k], buf_e[used:used + k] = a, e
        self._open[n] = (buf_a, buf_e, used + k)
        if used + k >= self.max_episode_frames:
            self._close(n)

    def _close(self, n: int) -> None:
        if n not in self._open:
            return
        buf_a, buf_e, used = self._open.pop(n)
        self._open_bytes -= buf_a.nbytes + buf_e.nbytes
        if used == buf_a.shape[0]:
            self._push(buf_a, buf_e)
        elif used:
            self._push(buf_a[:used].copy(), buf_e[:used].copy())

    def _push(self, a: np.ndarray, e: np.ndarray) -> None:
        a, e = np.ascontiguousarray(a), np.ascontiguousarray(e)
        if a.nbytes + e.nbytes > self.max_bytes:
            raise ValueError(f"one episode ({a.nbytes + e.nbytes} B) exceeds max_bytes ({self.max_bytes} B)")
        self._episodes.append((a, e))
        self._stored_bytes += a.nbytes + e.nbytes
        self.episodes_added += 1
        self._evict()

    def _evict(self) -> None:
        while self._stored_bytes + self._open_bytes > self.max_bytes:
            if not self._episodes:  # open buffers alone are over budget: finish the longest one
                self._close(max(self._open, key=lambda n: self._open[n][2]))
                continue
            a, e = self._episodes.popleft()
            self._stored_bytes -= a.nbytes + e.nbytes
            self.episodes_evicted += 1

    # -- reading ----------------------------------------------------------------------------
    def __len__(self) -> int:
        """Number of finished episodes stored."""
        return len(self._episodes)

    def episode(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """The i-th finished episode (0 = oldest) as (agent, expert) uint8 [T, 48, 48] arrays."""
        return self._episodes[i]

    def lengths(self) -> np.ndarray:
        """Frame counts of the finished episodes, oldest first."""
        return np.array([a.shape[0] for a, _ in self._episodes], dtype=np.int64)

    def sequences(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """What a batch may sample: the finished episodes (oldest first), then the open ones so far (views)."""
        return list(self._episodes) + [(a[:u], e[:u]) for a, e, u in self._open.values() if u]

    @property
    def num_frames(self) -> int:
        """Stored (agent, expert) frame pairs, open episodes included."""
        return sum(a.shape[0] for a, _ in self._episodes) + sum(u for _, _, u in self._open.values())

    @property
    def nbytes(self) -> int:
        """Bytes of frame payload held (finished + open buffers' capacity), at most ``max_bytes`` after any add."""
        return self._stored_bytes + self._open_bytes

    @property
    def bytes_per_frame(self) -> float:
        """Payload bytes per stored time step (agent + expert image: 2 * 48 * 48 = 4608 B; more while
        open buffers have spare capacity)."""
        n = self.num_frames
        return self.nbytes / n if n else float(2 * FRAME * FRAME)

    @property
    def mean_episode_length(self) -> float:
        """Mean frame count of the finished episodes (of the open ones while none has finished; nan when
        empty): EESP scales its windows with it."""
        if self._episodes:
            return float(self.lengths().mean())
        open_lengths = [u for _, _, u in self._open.values() if u]
        return float(np.mean(open_lengths)) if open_lengths else float("nan")
