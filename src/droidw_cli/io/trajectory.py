"""Trajectory files: TUM, KITTI and EuRoC CSV.  Poses are camera-to-world.

* TUM: ``timestamp tx ty tz qx qy qz qw`` (quaternion **x-y-z-w**), ``#`` comments.
* KITTI: 12 numbers a line, the row-major top 3×4 of the pose; no timestamps
  (they are the line index, or come from a separate times file).
* EuRoC CSV: ``#timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...``
  (quaternion **w-x-y-z**, nanoseconds).

Mixing xyzw and wxyz is the classic bug of this field: every conversion goes
through :func:`pose_from_tq` / :func:`tq_from_pose`, which take and return
xyzw explicitly.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from droidw_cli.errors import InputError

FORMATS = ("tum", "kitti", "euroc")


@dataclass(frozen=True)
class Trajectory:
    """Timestamps (N,) float64 seconds and camera-to-world poses (N, 4, 4) float64."""

    timestamps: np.ndarray
    poses: np.ndarray

    def __post_init__(self) -> None:
        if self.poses.ndim != 3 or self.poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must be (N, 4, 4), got {self.poses.shape}")
        if self.timestamps.shape != (self.poses.shape[0],):
            raise ValueError("timestamps and poses differ in length")

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) camera centres in the world frame."""
        return self.poses[:, :3, 3]

    def subset(self, index: np.ndarray) -> "Trajectory":
        return Trajectory(self.timestamps[index], self.poses[index])


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions, x-y-z-w order → (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - z * w)
    r[..., 0, 2] = 2 * (x * z + y * w)
    r[..., 1, 0] = 2 * (x * y + z * w)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - x * w)
    r[..., 2, 0] = 2 * (x * z - y * w)
    r[..., 2, 1] = 2 * (y * z + x * w)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def matrix_to_quat_xyzw(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices → (..., 4) unit quaternions x-y-z-w with w ≥ 0.

    Shepperd's method: pick the largest of (trace, diagonal) for stability.
    """
    r = np.asarray(r, dtype=np.float64)
    flat = r.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for k, m in enumerate(flat):  # per pose, not per pixel: trajectories are short
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            out[k] = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
        elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
            s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            out[k] = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
        elif m[1, 1] > m[2, 2]:
            s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            out[k] = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
        else:
            s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            out[k] = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    out /= np.linalg.norm(out, axis=-1, keepdims=True)
    out[out[:, 3] < 0] *= -1
    return out.reshape(r.shape[:-2] + (4,))


def pose_from_tq(t: np.ndarray, q_xyzw: np.ndarray) -> np.ndarray:
    """(N, 3) translations and (N, 4) x-y-z-w quaternions → (N, 4, 4) poses."""
    t = np.asarray(t, dtype=np.float64).reshape(-1, 3)
    poses = np.tile(np.eye(4), (t.shape[0], 1, 1))
    poses[:, :3, :3] = quat_xyzw_to_matrix(np.asarray(q_xyzw).reshape(-1, 4))
    poses[:, :3, 3] = t
    return poses


def tq_from_pose(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 4, 4) poses → ((N, 3) translations, (N, 4) x-y-z-w quaternions)."""
    return poses[:, :3, 3].copy(), matrix_to_quat_xyzw(poses[:, :3, :3])


def _numeric_rows(path: Path, ncols: tuple[int, ...], delimiter: str | None = None,
                  extra_ok: bool = False) -> list[tuple[int, list[float]]]:
    """Parse the numeric lines of a text file, reporting the first bad one by number.

    With ``extra_ok`` a line needs at least ``ncols[0]`` numbers and is cut to that many.
    """
    if not path.is_file():
        raise InputError(f"trajectory file not found: {path}")
    rows = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            s = line.strip()
            if not s or s.startswith("#") or s.startswith("%"):
                continue
            parts = [p for p in (s.split(delimiter) if delimiter else s.replace(",", " ").split()) if p.strip()]
            try:
                values = [float(p) for p in parts]
            except ValueError:
                raise InputError(f"{path}:{lineno}: not a number in line {s[:60]!r}") from None
            if extra_ok and len(values) >= ncols[0]:
                values = values[:ncols[0]]
            elif extra_ok:
                raise InputError(f"{path}:{lineno}: expected at least {ncols[0]} numbers, found {len(values)}")
            elif len(values) not in ncols:
                want = " or ".join(str(n) for n in ncols)
                raise InputError(f"{path}:{lineno}: expected {want} numbers, found {len(values)}")
            if not np.all(np.isfinite(values)):
                raise InputError(f"{path}:{lineno}: NaN or infinite value")
            rows.append((lineno, values))
    if not rows:
        raise InputError(f"{path}: no poses found")
    return rows


def _check_quats(path: Path, rows: list[tuple[int, list[float]]], q: np.ndarray) -> None:
    norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(norms < 1e-8)
    if bad.size:
        raise InputError(f"{path}:{rows[bad[0]][0]}: zero quaternion")


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM trajectory: ``t tx ty tz qx qy qz qw`` per line."""
    path = Path(path)
    rows = _numeric_rows(path, (8,))
    a = np.array([v for _, v in rows])
    _check_quats(path, rows, a[:, 4:8])
    return Trajectory(a[:, 0].copy(), pose_from_tq(a[:, 1:4], a[:, 4:8]))


def read_kitti(path: str | Path, times: str | Path | None = None) -> Trajectory:
    """Read a KITTI trajectory (3×4 row-major a line).  Timestamps: the times file or the line index."""
    path = Path(path)
    rows = _numeric_rows(path, (12,))
    a = np.array([v for _, v in rows]).reshape(-1, 3, 4)
    poses = np.tile(np.eye(4), (a.shape[0], 1, 1))
    poses[:, :3, :] = a
    if times is not None:
        t = np.array([v[0] for _, v in _numeric_rows(Path(times), (1,))])
        if t.shape[0] != poses.shape[0]:
            raise InputError(f"{times}: {t.shape[0]} timestamps for {poses.shape[0]} poses")
    else:
        t = np.arange(poses.shape[0], dtype=np.float64)
    return Trajectory(t, poses)


def read_euroc(path: str | Path) -> Trajectory:
    """Read an EuRoC CSV: ns timestamp, position, quaternion **w-x-y-z**, extra columns ignored."""
    rows = _numeric_rows(Path(path), (8,), delimiter=",", extra_ok=True)
    a = np.array([v for _, v in rows])
    q_xyzw = a[:, [5, 6, 7, 4]]  # EuRoC stores w first
    _check_quats(path, rows, q_xyzw)
    return Trajectory(a[:, 0] * 1e-9, pose_from_tq(a[:, 1:4], q_xyzw))


def detect_format(path: str | Path) -> str:
    """Guess the format from the extension and the first data line."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"trajectory file not found: {path}")
    if path.suffix.lower() == ".csv":
        return "euroc"
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            s = line.strip()
            if not s or s.startswith(("#", "%")):
                continue
            n = len(s.replace(",", " ").split())
            if n == 8:
                return "tum"
            if n == 12:
                return "kitti"
            raise InputError(f"{path}: cannot tell the trajectory format from a line of {n} numbers; pass --format")
    raise InputError(f"{path}: no poses found")


def read_trajectory(path: str | Path, fmt: str = "auto") -> Trajectory:
    """Read a trajectory in ``tum``, ``kitti``, ``euroc`` or ``auto``-detected format."""
    fmt = detect_format(path) if fmt == "auto" else fmt
    readers = {"tum": read_tum, "kitti": read_kitti, "euroc": read_euroc}
    if fmt not in readers:
        raise InputError(f"unknown trajectory format {fmt!r} (use one of {', '.join(FORMATS)})")
    return readers[fmt](path)


def format_trajectory(traj: Trajectory, fmt: str = "tum") -> str:
    """The text of a trajectory file in the given format."""
    t, q = tq_from_pose(traj.poses)
    if fmt == "tum":
        lines = [f"{ts:.6f} " + " ".join(f"{v:.9f}" for v in (*tt, *qq)) for ts, tt, qq in zip(traj.timestamps, t, q)]
        return "# timestamp tx ty tz qx qy qz qw\n" + "\n".join(lines) + "\n"
    if fmt == "kitti":
        return "\n".join(" ".join(f"{v:.9e}" for v in p[:3, :].ravel()) for p in traj.poses) + "\n"
    if fmt == "euroc":
        header = "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"
        lines = [f"{int(round(ts * 1e9))}," + ",".join(f"{v:.9f}" for v in (*tt, qq[3], qq[0], qq[1], qq[2]))
                 for ts, tt, qq in zip(traj.timestamps, t, q)]
        return header + "\n".join(lines) + "\n"
    raise InputError(f"unknown trajectory format {fmt!r} (use one of {', '.join(FORMATS)})")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write a text file via a temporary name and an atomic rename (no partial files)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_trajectory(path: str | Path, traj: Trajectory, fmt: str = "tum") -> None:
    """Write a trajectory atomically in ``tum``, ``kitti`` or ``euroc`` format."""
    atomic_write_text(path, format_trajectory(traj, fmt))


def atomic_write_bytes(path: str | Path, payload: bytes) -> None:
    """Write a file via a temporary name in the same folder and an atomic rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
