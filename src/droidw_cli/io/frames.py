"""Frames and frame sources: the base that every input type builds on.

:class:`Frame` (one decoded frame), :class:`Selection` (which raw frames are
kept), :class:`FrameSource` (a re-iterable stream of frames) and the decoding
helpers.  The sources themselves live in :mod:`~droidw_cli.io.sources` (video,
image folder) and :mod:`~droidw_cli.io.datasets` (TUM/Bonn, EuRoC, KITTI);
:func:`droidw_cli.io.input.open_source` picks one from a path.

Every source yields :class:`Frame` objects one at a time (memory stays
bounded), and ``iter(source)`` can be called again: each call reopens the
data, so a second pass (the trajectory filler) sees the same frames.

Selection: raw frames ``start, start + stride, …`` are kept, at most
``max_frames`` of them (0 = all).  ``Frame.index`` is the position in that
selection (0, 1, 2, …), so the raw index is ``start + index · stride``.
A corrupt frame is skipped with a :class:`CorruptFrameWarning`; the indices
of the other frames do not change (a gap is left).
"""

from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from droidw_cli.errors import ConfigError, InputError

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")


class CorruptFrameWarning(UserWarning):
    """A frame could not be decoded and was skipped."""


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame: selection index, time in seconds, RGB image and optional metric depth.

    ``image`` is H×W×3 uint8 RGB; ``depth`` is H×W float32 metres (0 = invalid) or None.
    """

    index: int
    timestamp: float
    image: np.ndarray
    depth: np.ndarray | None = None


@dataclass(frozen=True)
class Selection:
    """Which raw frames a source yields: ``start, start + stride, …``, at most ``max_frames`` (0 = all)."""

    stride: int = 1
    start: int = 0
    max_frames: int = 0

    def __post_init__(self) -> None:
        if int(self.stride) != self.stride or self.stride < 1:
            raise ConfigError(f"stride must be an integer ≥ 1, got {self.stride}")
        if int(self.start) != self.start or self.start < 0:
            raise ConfigError(f"start must be an integer ≥ 0, got {self.start}")
        if int(self.max_frames) != self.max_frames or self.max_frames < 0:
            raise ConfigError(f"max_frames must be an integer ≥ 0 (0 = all), got {self.max_frames}")

    def count(self, n_raw: int) -> int:
        """Number of selected frames out of ``n_raw`` raw frames."""
        n = len(range(self.start, max(n_raw, 0), self.stride))
        return min(n, self.max_frames) if self.max_frames else n

    def indices(self, n_raw: int) -> range:
        """Raw indices selected out of ``n_raw`` raw frames."""
        return range(self.start, self.start + self.count(n_raw) * self.stride, self.stride)

    def position(self, raw: int) -> int | None:
        """Selection index of raw frame ``raw``, or None if it is not selected (ignores max_frames)."""
        if raw < self.start or (raw - self.start) % self.stride:
            return None
        return (raw - self.start) // self.stride


def check_fps(fps: float) -> float:
    """``fps`` as a float; ConfigError unless it is a positive finite number."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"fps must be a positive number, got {fps}")
    return value


def warn_corrupt(message: str) -> None:
    warnings.warn(message, CorruptFrameWarning, stacklevel=3)


def _file_bytes(path: Path) -> np.ndarray | None:
    """The file's bytes as a uint8 array (for cv2.imdecode, which handles any path encoding); None if unreadable or empty."""
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError:
        return None
    return data if data.size else None


def decode_rgb(path: Path) -> np.ndarray | None:
    """Read an image file as H×W×3 uint8 RGB (grey and 16-bit images are converted); None if undecodable."""
    import cv2

    data = _file_bytes(path)
    if data is None:
        return None
    bgr = cv2.imdecode(data, cv2.IMREAD_COLOR)
    if bgr is None or bgr.ndim != 3 or bgr.shape[2] != 3:
        return None
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def decode_depth(path: Path, scale: float) -> np.ndarray | None:
    """Read a uint16 depth PNG as float32 metres (value / scale; 0 stays 0 = invalid); None if undecodable."""
    import cv2

    data = _file_bytes(path)
    if data is None:
        return None
    raw = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if raw is None or raw.ndim != 2:
        return None
    return (raw.astype(np.float32) / np.float32(scale)).astype(np.float32)


def png_size(path: Path) -> tuple[int, int] | None:
    """(H, W) from a PNG file's header (no decoding); None when it is not a readable PNG."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError:
        return None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[20:24], "big"), int.from_bytes(head[16:20], "big")


@dataclass(frozen=True)
class LazyDepth:
    """A depth image decoded only when called (RGB-D tracking reads the depth of its keyframes only).

    Calling it gives what an eager read gives: float32 metres, or None (with the same warning)
    when the file cannot be decoded or its size is not ``size``."""

    path: Path
    scale: float
    size: tuple[int, int]
    index: int

    def __call__(self) -> np.ndarray | None:
        depth = decode_depth(self.path, self.scale)
        if depth is None or depth.shape != self.size:
            warn_corrupt(f"{self.path}: unreadable or mis-sized depth; frame {self.index} kept without depth")
            return None
        return depth


class FrameSource(ABC):
    """A re-iterable stream of :class:`Frame`.

    Attributes: ``name`` (for messages and output names), ``size`` = (H, W) of
    the raw frames, ``intrinsics_hint`` (a :class:`~droidw_cli.io.calibration.Calibration`
    found with the data, or None), ``fps`` (the frame rate used for index-based
    timestamps).  ``len(source)`` is the number of frames iteration yields
    (for videos: computed from the container's frame count, see VideoSource).
    """

    name: str
    size: tuple[int, int]
    intrinsics_hint = None
    fps: float
    #: the calibration file found with the data (read by open_source into intrinsics_hint), or None
    calibration_file: Path | None = None
    #: which camera's projection a KITTI calib.txt gives (P0, P2, ...); other formats hold one camera
    calibration_camera: int = 0
    #: set (to the layout's name) where the layout always ships a calibration: without one it is an error
    calibration_expected: str | None = None
    #: why the calibration found with the data was not used (strict_calibration=False), or None
    calibration_problem: str | None = None

    def __init__(self, path: Path, selection: Selection, fps: float) -> None:
        self.path = Path(path)
        self.selection = selection
        self.fps = check_fps(fps)
        self.name = self.path.stem if self.path.is_file() else self.path.resolve().name

    @abstractmethod
    def __len__(self) -> int: ...

    @abstractmethod
    def __iter__(self) -> Iterator[Frame]: ...

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self.path)!r}, frames={len(self)}, size={self.size})"


def empty_selection(path: Path, sel: Selection) -> InputError:
    """The error for a selection that leaves no frames."""
    return InputError(f"{path}: no frames left after start={sel.start}, stride={sel.stride}, max_frames={sel.max_frames}")
