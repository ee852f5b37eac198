"""A sequence of frames as one video file: ``.mp4`` (H.264) and ``.webm`` (VP9) encoded by the
ffmpeg that the imageio-ffmpeg wheel ships, ``.gif`` by Pillow. Written atomically: the frames
go to a temporary file beside the target, renamed over it only once the video is complete, so
an interrupted or failed run leaves no file (and an existing one as it was); files that go
with the video (a legend's JSON record) are renamed with it, all or nothing.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

import numpy as np

from embree_rt.film import write_atomically

VIDEO_SUFFIXES = (".mp4", ".webm", ".gif")
DEFAULT_FPS = 24.0
# imageio-ffmpeg's quality scale is 0..10; the command line's --quality is 1..100.
DEFAULT_QUALITY = 50
FFMPEG_CODECS = {".mp4": "libx264", ".webm": "libvpx-vp9"}


def is_video(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a video (by its extension, case-insensitive)."""
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def check_video(
    path: str | os.PathLike, width: int, height: int, fps: float, quality: int | None = None
) -> None:
    """Raise ValueError naming ``path`` for what the video could not be written with: no
    encoder installed (the ``video`` extra), a frame rate not positive and finite, a quality
    outside 1..100, or an odd size for H.264/VP9 (their 4:2:0 colour halves the size)."""
    suffix = Path(path).suffix.lower()
    if not 0 < fps < float("inf"):
        raise ValueError(f"--fps: expected a positive number, got {fps:g}")
    if quality is not None and not 1 <= quality <= 100:
        raise ValueError(f"--quality: expected 1 to 100 for a video, got {quality}")
    if suffix in FFMPEG_CODECS:
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ValueError(
                f"{path}: writing {suffix} needs imageio-ffmpeg: pip install 'embree_rt[video]'"
            ) from None
        if width % 2 or height % 2:
            raise ValueError(
                f"{path}: {suffix} needs an even width and height, got {width}x{height}"
            )


class VideoWriter:
    """``with VideoWriter(path, fps, quality) as video: video.add(pixels)`` for each (h, w, 3)
    uint8 sRGB frame, all of one size. The file appears at ``path`` when the block ends without
    an error, and with it the files ``beside`` it (target path, writer(binary handle), as
    ``film.write_atomically`` takes them); otherwise none is left. ``quality`` 1..100 (None:
    ``DEFAULT_QUALITY``); a GIF holds its frames (one byte a pixel, palette-quantised) until
    the end."""

    def __init__(
        self,
        path: str | os.PathLike,
        fps: float = DEFAULT_FPS,
        quality: int | None = None,
        beside: list[tuple[Path, Callable[[BinaryIO], None]]] | None = None,
    ) -> None:
        self.path = Path(path)
        self.beside = list(beside or [])
        self.suffix = self.path.suffix.lower()
        self.fps = float(fps)
        self.quality = DEFAULT_QUALITY if quality is None else int(quality)
        self.temp = self.path.with_name(f".{self.path.stem}.{os.getpid()}.partial{self.suffix}")
        self.encoder = None
        self.gif_frames: list = []
        self.count = 0

    def __enter__(self) -> VideoWriter:
        return self

    def add(self, pixels: np.ndarray) -> None:
        """Append one (h, w, 3) uint8 frame."""
        pixels = np.ascontiguousarray(pixels, np.uint8)
        if self.suffix == ".gif":
            from PIL import Image

            self.gif_frames.append(Image.fromarray(pixels).quantize(256))
        else:
            if self.encoder is None:
                import imageio_ffmpeg

                height, width = pixels.shape[:2]
                self.encoder = imageio_ffmpeg.write_frames(
                    str(self.temp),
                    (width, height),
                    fps=self.fps,
                    codec=FFMPEG_CODECS[self.suffix],
                    quality=self.quality / 10.0,
                    macro_block_size=2,
                    ffmpeg_log_level="error",
                )
                self.encoder.send(None)
            self.encoder.send(pixels)
        self.count += 1

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        try:
            if self.encoder is not None:
                self.encoder.close()
            if kind is None and self.suffix == ".gif" and self.gif_frames:
                first, *rest = self.gif_frames
                first.save(
                    self.temp,
                    save_all=True,
                    append_images=rest,
                    duration=round(1000.0 / self.fps),
                    loop=0,
                )
            if kind is None and self.count:
                write_atomically(self.beside, written=[(self.temp, self.path)])
        finally:
            self.gif_frames = []
            self.temp.unlink(missing_ok=True)
