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
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.frames import Selection
from droidw_cli.io.sources import Entry, ListSource, find_hint

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
        self.intrinsics_hint = find_hint(folder, self.size)


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
        self.intrinsics_hint = self._hint(cam / "sensor.yaml")

    def _hint(self, yaml_path: Path):
        from droidw_cli.io.calibration import load_calibration

        if not yaml_path.is_file():
            return None
        try:
            return load_calibration(yaml_path, self.size)
        except InputError as exc:
            warnings.warn(f"ignoring the EuRoC calibration: {exc}", stacklevel=3)
            return None
