"""Contact sheet: a grid of a demonstration's frames in one PNG, to check a demo by eye."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from virl_quad.demo.demonstration import Demonstration


TITLE_PX = 18  # px, height of the title band


def contact_sheet(frames: np.ndarray, columns: int = 8, max_frames: int = 32, scale: int = 3,
                  gap: int = 2, fps: float = 0.0, title: str = "") -> np.ndarray:
    """Tile up to ``max_frames`` evenly spaced gray frames (T, H, W) into one uint8 image.

    Each frame is enlarged ``scale`` times (nearest neighbour) and frames are separated by
    ``gap`` px of white. Each tile is labelled with its time in s (``fps`` > 0) or else its
    frame index; a non-empty ``title`` (e.g. the gait) is written in a band above the grid.
    """
    import cv2

    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 3 or len(frames) == 0:
        raise ValueError(f"frames must be (T, H, W) with T > 0, got {frames.shape}")
    picks = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames))).round().astype(int))
    h, w = frames.shape[1] * scale, frames.shape[2] * scale
    columns = min(columns, len(picks))
    rows = int(np.ceil(len(picks) / columns))
    top = TITLE_PX if title else 0
    sheet = np.full((top + rows * (h + gap) + gap, columns * (w + gap) + gap), 255, np.uint8)
    if title:
        cv2.putText(sheet, title, (gap + 2, TITLE_PX - 5), cv2.FONT_HERSHEY_PLAIN, 1.0, 0, 1, cv2.LINE_AA)
    for n, i in enumerate(picks):
        r, c = divmod(n, columns)
        tile = cv2.resize(frames[i], (w, h), interpolation=cv2.INTER_NEAREST)
        label = f"{i / fps:.2f} s" if fps > 0 else str(i)
        cv2.putText(tile, label, (2, 11), cv2.FONT_HERSHEY_PLAIN, 0.8, 255, 1, cv2.LINE_AA)
        y, x = top + gap + r * (h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = tile
    return sheet


def save_contact_sheet(demo: Demonstration, path: str | os.PathLike, **kwargs) -> Path:
    """Write the contact sheet of ``demo`` as a PNG (tiles labelled with their time, titled with the
    demonstration's source, e.g. ``gait:trot``); returns the path."""
    import cv2

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), contact_sheet(demo.frames, fps=demo.fps, title=demo.source, **kwargs)):
        raise ValueError(f"cannot write image {path}")
    return path
