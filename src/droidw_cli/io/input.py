"""Open an input: detect its kind from the path and read the calibration found with it.

``open_source(path)`` picks the source from the path:

========================================  ====================================
path                                      source
========================================  ====================================
``*.mp4 / .avi / .mov / .mkv`` (+ m4v,    :class:`~droidw_cli.io.sources.VideoSource`
webm, mpg, mpeg, wmv)
folder with ``rgb.txt`` (or that file)    :class:`~droidw_cli.io.datasets.TumRgbdSource`
                                          (TUM / Bonn RGB-D)
EuRoC root, ``mav0`` or ``mav0/cam0``     :class:`~droidw_cli.io.datasets.EurocSource`
KITTI odometry sequence (``image_0/`` or  :class:`~droidw_cli.io.datasets.KittiSource`
``image_2/``, ``times.txt``, ``calib.txt``)
or its ``image_0`` / ``image_2`` folder
any other folder of jpg/png/bmp/tif       :class:`~droidw_cli.io.sources.ImageFolderSource`
========================================  ====================================

Calibration found with the data (``calib.txt``, EuRoC ``sensor.yaml``, KITTI
``calib.txt``) becomes ``source.intrinsics_hint``.  By default a file that
cannot be read is an error naming it and the formats droidw reads; with
``strict_calibration=False`` (``droidw track --calib FILE``, where the given
file wins) it is kept as ``source.calibration_problem`` for a warning instead.
"""

from __future__ import annotations

from pathlib import Path

from droidw_cli.errors import InputError
from droidw_cli.io.calibration import READABLE_FORMATS, load_calibration
from droidw_cli.io.datasets import EurocSource, KittiSource, TumRgbdSource, find_euroc_cam, find_kitti
from droidw_cli.io.frames import IMAGE_SUFFIXES, VIDEO_SUFFIXES, FrameSource, Selection, check_fps, empty_selection
from droidw_cli.io.sources import ImageFolderSource, VideoSource


def _check_nonempty(source: FrameSource) -> FrameSource:
    if len(source) == 0:
        raise empty_selection(source.path, source.selection)
    return source


def read_calibration_hint(source: FrameSource, strict: bool = True) -> FrameSource:
    """Read ``source.calibration_file`` into ``source.intrinsics_hint`` (checked against ``source.size``).

    A file that cannot be read raises :class:`InputError` naming it and the
    formats droidw reads when ``strict``; otherwise the hint stays None and
    the reason goes to ``source.calibration_problem``.  A layout that always
    ships a calibration (``calibration_expected``) without one is an error
    only when ``strict``.
    """
    path = source.calibration_file
    if path is None:
        if source.calibration_expected and strict:
            raise InputError(f"{source.path}: no calib.txt, which {source.calibration_expected} always has; add "
                             f"it, or pass --calib FILE or --calib auto")
        return source
    try:
        source.intrinsics_hint = load_calibration(path, source.size, camera=source.calibration_camera)
    except InputError as exc:
        if strict:
            raise InputError(f"{exc} (the calibration found with the input; droidw reads {READABLE_FORMATS}); "
                             f"pass --calib FILE or --calib auto to track without it") from None
        source.calibration_problem = str(exc)
    return source


def open_source(path: str | Path, *, stride: int = 1, start: int = 0, max_frames: int = 0, fps: float = 30.0,
                strict_calibration: bool = True) -> FrameSource:
    """Open a video, image folder, TUM/Bonn RGB-D folder, EuRoC or KITTI sequence (detected from ``path``).

    ``fps`` is used for timestamps when the data has none (image folders
    without timestamp names, videos that report no frame rate).  Raises
    :class:`InputError` for a missing path, an unknown file type, an empty
    folder or an unreadable video, and when the selection is empty.  The
    calibration found with the data is read by :func:`read_calibration_hint`
    (``strict_calibration``: its problems are errors, else warnings).
    """
    return read_calibration_hint(_open(path, stride, start, max_frames, fps), strict_calibration)


def _open(path: str | Path, stride: int, start: int, max_frames: int, fps: float) -> FrameSource:
    sel = Selection(stride=stride, start=start, max_frames=max_frames)
    fps = check_fps(fps)
    p = Path(path).expanduser()
    if not p.exists():
        raise InputError(f"{p}: no such file or folder")
    if p.is_file():
        suffix = p.suffix.lower()
        if suffix in VIDEO_SUFFIXES:
            return _check_nonempty(VideoSource(p, sel, fps))
        if p.name == "rgb.txt":
            return _check_nonempty(TumRgbdSource(p.parent, sel, fps))
        if suffix in IMAGE_SUFFIXES:
            raise InputError(f"{p}: a single image is not a sequence; pass the folder that holds the images")
        raise InputError(f"{p}: unknown input type {suffix or '(no suffix)'!r}; expected a video "
                         f"({', '.join(VIDEO_SUFFIXES)}) or a folder of images")
    if not p.is_dir():
        raise InputError(f"{p}: not a file or folder")
    if (p / "rgb.txt").is_file():
        return _check_nonempty(TumRgbdSource(p, sel, fps))
    cam = find_euroc_cam(p)
    if cam is not None:
        return _check_nonempty(EurocSource(cam, sel, fps))
    kitti = find_kitti(p)
    if kitti is not None:
        return _check_nonempty(KittiSource(*kitti, sel, fps))
    return _check_nonempty(ImageFolderSource(p, sel, fps))
