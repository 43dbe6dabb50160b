"""Video files and plain image folders (see :mod:`droidw_cli.io.frames` for the interface).

Image-folder timestamps
-----------------------
When **every** file stem is a number, the numbers may be timestamps:

* a stem with a fractional part (TUM ``1305031102.175304.png``) or any value
  ≥ 10⁶ → the numbers are seconds (unix time);
* all-integer stems ≥ 10¹⁷ → nanoseconds (EuRoC ``1403636579763555584.png``),
  divided by 10⁹;
* otherwise (integers below 10⁶, e.g. ``00000.jpg``) they are frame numbers and
  the timestamp is ``position / fps``.

Files are then ordered by value.  Any folder with a non-numeric stem uses
natural sort (``img2`` before ``img10``) and ``position / fps``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.frames import (IMAGE_SUFFIXES, Frame, FrameSource, LazyDepth, Selection, decode_depth, decode_rgb,
                                  empty_selection, png_size, warn_corrupt)

_NUMERIC_STEM = re.compile(r"^\d+(\.\d*)?$")
_MAX_CONSECUTIVE_READ_FAILURES = 16


def natural_key(name: str) -> tuple:
    """Sort key treating digit runs as numbers: ``img2`` < ``img10``."""
    parts = re.split(r"(\d+)", name.lower())
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in parts)


def list_images(folder: Path) -> list[Path]:
    """Image files directly in ``folder`` (hidden files ignored), unsorted."""
    return [p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES]


def stem_timestamps(stems: Sequence[str]) -> np.ndarray | None:
    """Seconds from numeric file stems per the module rule, or None when they are not timestamps."""
    if not stems or not all(_NUMERIC_STEM.match(s) for s in stems):
        return None
    values = np.array([float(s) for s in stems], dtype=np.float64)
    fractional = any("." in s for s in stems)
    if not fractional and values.max() >= 1e17:
        return np.array([int(s) for s in stems], dtype=np.float64) / 1e9
    if fractional or values.max() >= 1e6:
        return values
    return None


#: calibration files looked for in an input folder, in this order
CALIBRATION_NAMES = ("calib.txt", "calibration.txt", "calib.yaml")


def find_calibration_file(folder: Path) -> Path | None:
    """The first of :data:`CALIBRATION_NAMES` in ``folder``, or None (read by ``open_source``)."""
    for name in CALIBRATION_NAMES:
        if (folder / name).is_file():
            return folder / name
    return None


@dataclass(frozen=True)
class Entry:
    """One raw frame of a file-based source."""

    timestamp: float
    rgb: Path
    depth: Path | None = None


TUM_DEPTH_SCALE = 5000.0  # uint16 depth PNG units per metre (TUM, Bonn)


class ListSource(FrameSource):
    """A source whose raw frames are a list of image files (with optional depth PNGs)."""

    depth_scale = TUM_DEPTH_SCALE
    load_depth = True  # False: skip decoding the depth PNGs (a monocular run does not read them)
    strict_depth = False  # True (RGB-D runs): a depth image whose size differs from its frame is an error
    lazy_depth = False  # True: Frame.depth is a LazyDepth (decoded when called), its size checked from the PNG header

    def __init__(self, path: Path, selection: Selection, fps: float, entries: Sequence[Entry]) -> None:
        super().__init__(path, selection, fps)
        self.n_raw = len(entries)
        self._entries = [entries[i] for i in selection.indices(len(entries))]
        self.size = self._probe_size()

    def _probe_size(self) -> tuple[int, int]:
        for entry in self._entries:
            img = decode_rgb(entry.rgb)
            if img is not None:
                return int(img.shape[0]), int(img.shape[1])
        if not self._entries:  # before anything reads the size (a calibration file is checked against it)
            raise empty_selection(self.path, self.selection)
        raise InputError(f"{self.path}: none of the {len(self._entries)} selected images can be decoded")

    @property
    def timestamps(self) -> np.ndarray:
        """Timestamps of the selected frames (including any that turn out corrupt)."""
        return np.array([e.timestamp for e in self._entries], dtype=np.float64)

    def __len__(self) -> int:
        return len(self._entries)

    def depth_files(self) -> list[Path | None]:
        """The depth image paired with each selected frame (None: it has none)."""
        return [e.depth for e in self._entries]

    def __iter__(self) -> Iterator[Frame]:
        for k, entry in enumerate(self._entries):
            img = decode_rgb(entry.rgb)
            if img is None:
                warn_corrupt(f"{entry.rgb}: cannot decode the image; frame {k} skipped")
                continue
            if img.shape[:2] != self.size:
                warn_corrupt(f"{entry.rgb}: size {img.shape[1]}x{img.shape[0]} differs from "
                             f"{self.size[1]}x{self.size[0]}; frame {k} skipped")
                continue
            depth = None
            if entry.depth is not None and self.load_depth and self.lazy_depth:
                shape = png_size(entry.depth)
                if self.strict_depth and shape is not None and shape != img.shape[:2]:
                    raise InputError(f"{entry.depth}: depth image is {shape[1]}x{shape[0]}, its frame "
                                     f"{entry.rgb.name} is {img.shape[1]}x{img.shape[0]}")
                depth = LazyDepth(entry.depth, self.depth_scale, self.size, k)
            elif entry.depth is not None and self.load_depth:
                depth = decode_depth(entry.depth, self.depth_scale)
                if self.strict_depth and depth is not None and depth.shape != img.shape[:2]:
                    raise InputError(f"{entry.depth}: depth image is {depth.shape[1]}x{depth.shape[0]}, its frame "
                                     f"{entry.rgb.name} is {img.shape[1]}x{img.shape[0]}")
                if depth is None or depth.shape != self.size:
                    warn_corrupt(f"{entry.depth}: unreadable or mis-sized depth; frame {k} kept without depth")
                    depth = None
            yield Frame(k, float(entry.timestamp), img, depth)


class ImageFolderSource(ListSource):
    """A folder of jpg/jpeg/png/bmp/tif images; a ``calib.txt`` beside them is the intrinsics hint."""

    def __init__(self, folder: Path, selection: Selection, fps: float) -> None:
        files = list_images(folder)
        if not files:
            raise InputError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
        stamps = stem_timestamps([f.stem for f in files])
        if stamps is not None:
            order = np.argsort(stamps, kind="stable")
            files, times = [files[i] for i in order], stamps[order]
        else:
            files = sorted(files, key=lambda f: natural_key(f.name))
            times = np.arange(len(files), dtype=np.float64) / fps
        self.timestamps_from_names = stamps is not None
        super().__init__(folder, selection, fps, [Entry(float(t), f) for t, f in zip(times, files)])
        self.calibration_file = find_calibration_file(folder)


class VideoSource(FrameSource):
    """A video file decoded with ``cv2.VideoCapture``; timestamps are raw index / video fps.

    ``len()`` comes from the container's frame count (counted by decoding
    once when the container does not say).  Iteration trusts the decoder: it
    stops at the real end of the stream even if the header count is wrong, and
    a frame that fails to decode mid-stream is skipped with a warning.
    """

    def __init__(self, path: Path, selection: Selection, fps: float) -> None:
        super().__init__(path, selection, fps)
        import cv2

        cap = self._open()
        try:
            video_fps = cap.get(cv2.CAP_PROP_FPS)
            if math.isfinite(video_fps) and 0 < video_fps <= 1000:
                self.fps = float(video_fps)
            count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
            self._n_raw: int | None = int(count) if math.isfinite(count) and count > 0 else None
            first = None
            for _ in range(_MAX_CONSECUTIVE_READ_FAILURES):
                ok, first = cap.read()
                if ok and first is not None:
                    break
                first = None
            if first is None:
                raise InputError(f"{path}: the video has no decodable frames")
            self.size = (int(first.shape[0]), int(first.shape[1]))
        finally:
            cap.release()

    def _open(self):
        import cv2

        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise InputError(f"{self.path}: cannot open the video (unsupported codec or corrupt file)")
        return cap

    @property
    def n_raw(self) -> int:
        """Raw frames in the video (container header, or counted by decoding once)."""
        if self._n_raw is None:
            cap = self._open()
            n, fails = 0, 0
            try:
                while fails < _MAX_CONSECUTIVE_READ_FAILURES:
                    if cap.grab():
                        n, fails = n + 1 + fails, 0
                    else:
                        fails += 1
            finally:
                cap.release()
            self._n_raw = n
        return self._n_raw

    def __len__(self) -> int:
        return self.selection.count(self.n_raw)

    def __iter__(self) -> Iterator[Frame]:
        import cv2

        sel, n_raw = self.selection, self._n_raw
        cap = self._open()
        try:
            raw, pending = 0, []  # pending: raw indices whose grab failed (corrupt unless the stream ended)
            while True:
                pos = sel.position(raw)
                if pos is not None and sel.max_frames and pos >= sel.max_frames:
                    break
                if not cap.grab():
                    if n_raw is not None and raw >= n_raw:
                        break
                    pending.append(raw)
                    if len(pending) >= _MAX_CONSECUTIVE_READ_FAILURES:
                        if n_raw is not None:
                            warn_corrupt(f"{self.path}: decoding stopped at frame {pending[0]} of {n_raw}; the rest is skipped")
                        break
                    raw += 1
                    continue
                for bad in pending:
                    if sel.position(bad) is not None:
                        warn_corrupt(f"{self.path}: cannot decode video frame {bad}; frame {sel.position(bad)} skipped")
                pending = []
                if pos is not None:
                    ok, bgr = cap.retrieve()
                    if not ok or bgr is None or bgr.ndim != 3 or bgr.shape[:2] != self.size:
                        warn_corrupt(f"{self.path}: cannot decode video frame {raw}; frame {pos} skipped")
                    else:
                        yield Frame(pos, raw / self.fps, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
                raw += 1
        finally:
            cap.release()
