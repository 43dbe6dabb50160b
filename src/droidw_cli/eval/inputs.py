"""Loading the two trajectories of an evaluation from the command line's arguments."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from droidw_cli.errors import InputError, UserError
from droidw_cli.io.trajectory import Trajectory, detect_format, read_kitti, read_trajectory

RUN_TRAJECTORY = "traj.txt"
#: the timestamps file of a KITTI sequence folder (one line per pose), as ``droidw synth --layout kitti`` writes
KITTI_TIMES = "times.txt"


@dataclass(frozen=True, eq=False)
class LoadedTrajectory:
    """A trajectory, where it came from, its format and whether it has real timestamps."""

    traj: Trajectory
    path: Path
    fmt: str
    has_timestamps: bool


def resolve_estimate_path(path: str | Path) -> Path:
    """A trajectory file, or a run folder holding ``traj.txt``."""
    p = Path(path)
    if p.is_dir():
        p = p / RUN_TRAJECTORY
        if not p.is_file():
            raise InputError(f"run folder {p.parent} has no {RUN_TRAJECTORY}")
    if not p.is_file():
        raise InputError(f"trajectory file not found: {p}")
    return p


def load(path: str | Path, fmt: str = "auto", times: str | Path | None = None, role: str = "est") -> LoadedTrajectory:
    """Read a trajectory; KITTI files get timestamps only from a ``times`` file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"trajectory file not found: {p}")
    resolved = detect_format(p) if fmt == "auto" else fmt
    if resolved == "kitti":
        return LoadedTrajectory(read_kitti(p, times), p, resolved, times is not None)
    if times is not None:
        raise UserError(f"--{role}-times only applies to KITTI files, but {p} is {resolved.upper()}")
    return LoadedTrajectory(read_trajectory(p, resolved), p, resolved, True)


def with_folder_times(loaded: LoadedTrajectory, other: LoadedTrajectory, flag: str) -> LoadedTrajectory:
    """A KITTI trajectory without timestamps, compared with a timestamped ``other``, takes its times from
    :data:`KITTI_TIMES` in its own folder when there is one (``droidw synth --layout kitti`` writes
    ``poses.txt`` beside it); unchanged otherwise.  A times file whose length differs is an error."""
    times = loaded.path.parent / KITTI_TIMES
    if loaded.has_timestamps or not other.has_timestamps or not times.is_file():
        return loaded
    try:
        traj = read_kitti(loaded.path, times)
    except InputError as exc:
        raise InputError(f"{exc} (read as the times of {loaded.path.name}, which has none; give them with "
                         f"{flag} FILE)") from None
    return LoadedTrajectory(traj, loaded.path, loaded.fmt, True)


def pairing_by_index(gt: LoadedTrajectory, est: LoadedTrajectory) -> bool:
    """True when neither trajectory has timestamps (pair by index); an error when only one lacks them."""
    if gt.has_timestamps and est.has_timestamps:
        return False
    if not gt.has_timestamps and not est.has_timestamps:
        return True
    lacking, flag = (gt, "--gt-times") if not gt.has_timestamps else (est, "--est-times")
    raise InputError(
        f"{lacking.path} is a KITTI file without timestamps but the other trajectory has them; "
        f"give its times with {flag} FILE"
    )
