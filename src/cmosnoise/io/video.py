"""Video output: H.264 MP4 written frame by frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np


class VideoWriter:
    """H.264 MP4 written frame by frame (imageio with the ffmpeg binary shipped by imageio-ffmpeg)."""

    def __init__(self, path: str | Path, fps: float, comment: str | None = None, gain: float = 1.0):
        """``comment``: the video's metadata comment (what it shows: the display gain); ``gain``: every frame's
        8-bit picture multiplied by it (a display stretch), clipped to 255."""
        import imageio.v2 as iio2

        self.gain = float(gain)
        self._writer = iio2.get_writer(
            str(path), fps=fps, codec="libx264", quality=8, macro_block_size=2, ffmpeg_log_level="error",
            pixelformat="yuv420p", output_params=["-metadata", f"comment={comment}"] if comment else None,
        )

    def append(self, frame: np.ndarray) -> None:
        if self.gain != 1.0:
            frame = np.clip(np.rint(frame.astype(np.float32) * np.float32(self.gain)), 0, 255).astype(np.uint8)
        if frame.ndim == 2:
            frame = np.repeat(frame[..., None], 3, axis=2)
        rows, cols = frame.shape[:2]
        self._writer.append_data(np.ascontiguousarray(frame[: rows - rows % 2, : cols - cols % 2]))  # yuv420p: even sizes

    def close(self) -> None:
        self._writer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
