"""Dataset layouts: TUM / Bonn RGB-D folders and EuRoC ``mav0/cam0`` sequences.

TUM / Bonn RGB-D
    ``rgb.txt`` and ``depth.txt`` list ``timestamp relative/path.png``.  Each
    RGB frame takes the depth image nearest in time if it is within
    ``max_dt`` = 0.02 s, else it has no depth.  Depth PNGs are uint16 with 5000
    units per metre; 0 means no measurement.  A ``calib.txt`` in the folder is
    the intrinsics hint.

EuRoC
    ``cam0/data.csv`` lists ``timestamp [ns], filename`` for ``cam0/data/``.
    Grey images are expanded to three RGB channels.  ``cam0/sensor.yaml``
    (``intrinsics: [fu, fv, cu, cv]``, ``distortion_coefficients``) is the hint.

KITTI odometry
    A sequence folder holds ``image_0/`` (left grey camera) and/or
    ``image_2/`` (left colour camera) with ``000000.png, 000001.png, …``,
    ``times.txt`` (one timestamp in seconds a line, one line per image) and
    ``calib.txt`` (``P0:`` … ``P3:`` projection matrices, see
    :mod:`droidw_cli.io.calibration`).  When both image folders exist
    ``image_0`` is read: the odometry benchmark's poses are those of the left
    grey camera.  Passing ``image_0`` (or ``image_2``) itself reads that
    camera, when its parent has ``times.txt``.  The hint is the ``P`` line of
    the camera read (P0 for image_0, P2 for image_2); KITTI always ships
    calib.txt, so without it ``droidw track`` needs ``--calib``.  Grey images
    are expanded to three RGB channels.  Other folders of the layout
    (``image_1``, ``depth/`` written by ``droidw synth --layout kitti``) are
    not read.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.frames import Selection
from droidw_cli.io.sources import Entry, ListSource, find_calibration_file, list_images, natural_key

TUM_MAX_DT = 0.02  # seconds


def _read_listing(path: Path, delimiter: str | None = None) -> tuple[np.ndarray, list[str]]:
    """``timestamp name`` lines of a TUM / EuRoC listing; ``#`` lines are comments."""
    stamps, names = [], []
    for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = [p.strip() for p in line.split(delimiter)]
        try:
            if len(parts) < 2:
                raise ValueError
            stamps.append(float(parts[0]) if delimiter is None else int(parts[0]))
        except ValueError:
            raise InputError(f"{path}:{lineno}: expected 'timestamp filename', got {line!r}") from None
        names.append(parts[1])
    return np.array(stamps, dtype=np.float64), names


def associate_nearest(query: np.ndarray, ref: np.ndarray, max_dt: float) -> np.ndarray:
    """For each ``query`` time, the index of the nearest ``ref`` time within ``max_dt``, else -1.

    Vectorised: sort ``ref``, ``searchsorted`` the queries and compare the two
    neighbours.
    """
    query = np.asarray(query, dtype=np.float64)
    out = np.full(query.shape, -1, dtype=np.int64)
    if query.size == 0 or len(ref) == 0:
        return out
    order = np.argsort(ref, kind="stable")
    ref_sorted = np.asarray(ref, dtype=np.float64)[order]
    hi = np.clip(np.searchsorted(ref_sorted, query), 1, len(ref_sorted) - 1) if len(ref_sorted) > 1 else np.zeros(query.shape, np.int64)
    lo = np.maximum(hi - 1, 0)
    pick = np.where(np.abs(ref_sorted[lo] - query) <= np.abs(ref_sorted[hi] - query), lo, hi)
    ok = np.abs(ref_sorted[pick] - query) <= max_dt
    out[ok] = order[pick[ok]]
    return out


class TumRgbdSource(ListSource):
    """A TUM or Bonn RGB-D folder (``rgb.txt`` [+ ``depth.txt``])."""

    def __init__(self, folder: Path, selection: Selection, fps: float, max_dt: float = TUM_MAX_DT) -> None:
        rgb_t, rgb_names = _read_listing(folder / "rgb.txt")
        if not rgb_names:
            raise InputError(f"{folder / 'rgb.txt'}: lists no images")
        depth_paths: list[Path | None] = [None] * len(rgb_names)
        self.has_depth = (folder / "depth.txt").is_file()
        if self.has_depth:
            d_t, d_names = _read_listing(folder / "depth.txt")
            match = associate_nearest(rgb_t, d_t, max_dt)
            depth_paths = [folder / d_names[m] if m >= 0 else None for m in match]
        order = np.argsort(rgb_t, kind="stable")
        entries = [Entry(float(rgb_t[i]), folder / rgb_names[i], depth_paths[i]) for i in order]
        super().__init__(folder, selection, fps, entries)
        self.calibration_file = find_calibration_file(folder)


def find_euroc_cam(path: Path) -> Path | None:
    """The ``cam0`` folder if ``path`` is a EuRoC sequence root, its ``mav0`` or ``cam0`` itself."""
    for cand in (path / "mav0" / "cam0", path / "cam0", path):
        if (cand / "data.csv").is_file() and (cand / "data").is_dir():
            return cand
    return None


class EurocSource(ListSource):
    """EuRoC MAV ``cam0`` images (grey → RGB) with nanosecond timestamps."""

    def __init__(self, cam: Path, selection: Selection, fps: float, name: str | None = None) -> None:
        stamps, names = _read_listing(cam / "data.csv", delimiter=",")
        if not names:
            raise InputError(f"{cam / 'data.csv'}: lists no images")
        order = np.argsort(stamps, kind="stable")
        entries = [Entry(float(stamps[i]) / 1e9, cam / "data" / names[i]) for i in order]
        super().__init__(cam, selection, fps, entries)
        self.name = name or (cam.parent.parent.name if cam.parent.name == "mav0" else cam.name)
        yaml_path = cam / "sensor.yaml"
        self.calibration_file = yaml_path if yaml_path.is_file() else None


#: KITTI cameras looked for in a sequence folder, in order of preference (left grey, left colour)
KITTI_CAMERAS = (0, 2)
_KITTI_IMAGE_DIR = re.compile(r"image_([0-3])")


def find_kitti(path: Path) -> tuple[Path, int] | None:
    """(sequence folder, camera) if ``path`` is a KITTI odometry sequence, or its ``image_N`` folder with
    ``times.txt`` in the parent; else None."""
    for cam in KITTI_CAMERAS:
        if (path / f"image_{cam}").is_dir():
            return path, cam
    m = _KITTI_IMAGE_DIR.fullmatch(path.name)
    if m is not None and (path.parent / "times.txt").is_file():
        return path.parent, int(m.group(1))
    return None


def read_times(path: Path) -> np.ndarray:
    """KITTI ``times.txt``: one timestamp in seconds a line (blank lines skipped), strictly increasing."""
    if not path.is_file():
        raise InputError(f"{path.parent}: a KITTI sequence needs times.txt (one timestamp in seconds a line)")
    stamps: list[float] = []
    for lineno, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        try:
            t = float(s)
        except ValueError:
            t = math.nan
        if not math.isfinite(t):
            raise InputError(f"{path}:{lineno}: expected one timestamp in seconds, got {s[:60]!r}")
        if stamps and t <= stamps[-1]:
            raise InputError(f"{path}:{lineno}: timestamp {s} does not increase (previous {stamps[-1]:g})")
        stamps.append(t)
    if not stamps:
        raise InputError(f"{path}: holds no timestamps")
    return np.array(stamps, dtype=np.float64)


class KittiSource(ListSource):
    """A KITTI odometry sequence: ``image_<camera>/`` images, ``times.txt`` timestamps, ``calib.txt`` P<camera>."""

    calibration_expected = "a KITTI odometry sequence"

    def __init__(self, folder: Path, camera: int, selection: Selection, fps: float) -> None:
        images = folder / f"image_{camera}"
        files = sorted(list_images(images), key=lambda f: natural_key(f.name))
        if not files:
            raise InputError(f"{images}: no images in this KITTI image folder")
        stamps = read_times(folder / "times.txt")
        if len(stamps) != len(files):
            raise InputError(f"{folder / 'times.txt'}: {len(stamps)} timestamps for {len(files)} images in "
                             f"{images.name}/ (KITTI has one line per image)")
        super().__init__(folder, selection, fps, [Entry(float(t), f) for t, f in zip(stamps, files)])
        self.calibration_camera = camera
        self.calibration_file = folder / "calib.txt" if (folder / "calib.txt").is_file() else None
