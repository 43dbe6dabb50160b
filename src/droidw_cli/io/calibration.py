"""Pinhole camera calibration: reading, validating and writing.

Three file formats are read (:data:`READABLE_FORMATS` says so in error messages):

* **text** — one line ``fx fy cx cy [k1 k2 p1 p2 [k3]]`` (whitespace or commas,
  ``#`` comments allowed).  This is also what :func:`write_calibration` writes.
* **YAML** — keys ``fx, fy, cx, cy`` (optionally prefixed ``Camera.`` as in
  ORB-SLAM files) or ``intrinsics: [fx, fy, cx, cy]`` (EuRoC ``sensor.yaml``),
  with optional distortion as ``distortion: [...]``,
  ``distortion_coefficients: [...]`` or keys ``k1 k2 p1 p2 [k3]``.
* **KITTI odometry** ``calib.txt`` — lines ``P0: …`` to ``P3: …`` (and
  ``Tr: …``), each a row-major 3×4 matrix.  The rectified projection of camera
  i is P_i = K [I | t_i], so fx = P[0,0], fy = P[1,1], cx = P[0,2],
  cy = P[1,2]; the images are rectified, hence no distortion.  Camera 0 (the
  left grey camera, ``image_0``) is read unless another is asked for (a
  KITTI source reading ``image_2`` asks for P2).

Distortion is OpenCV's radial-tangential model (k1, k2, p1, p2[, k3]).  It acts
on normalised coordinates, so resizing or cropping the image changes only
fx, fy, cx, cy; the coefficients stay the same.

``load_calibration("auto")`` returns ``None``: the intrinsics are unknown and
tracking estimates them (focal search, principal point at the image centre).

Intrinsics follow the pixel-centre convention of :mod:`droidw_cli.geometry.camera`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from droidw_cli.errors import InputError, yaml_problem
from droidw_cli.geometry.camera import resize_crop_intrinsics, working_size

_DISTORTION_LENGTHS = (0, 4, 5)
_RADTAN_NAMES = ("radial-tangential", "radtan", "plumb_bob", "pinhole-radtan")
_YAML_SUFFIXES = (".yaml", ".yml")
_KITTI_LINE = re.compile(r"^\s*P[0-3]\s*:", re.M)
#: the formats load_calibration reads, for error messages
READABLE_FORMATS = ("one line 'fx fy cx cy [k1 k2 p1 p2 [k3]]', YAML (fx fy cx cy, or intrinsics: [fx, fy, cx, cy]) "
                    "or KITTI's calib.txt (P0: … P3: …)")
#: plausible focal lengths, × the image's larger side: fields of view from about 169° down to about 0.6°
FOCAL_RANGE = (0.05, 100.0)
#: at most this ratio between fx and fy (pixels are close to square)
MAX_ASPECT = 3.0


@dataclass(frozen=True)
class Calibration:
    """Pinhole intrinsics in pixels plus optional radial-tangential distortion."""

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy, *self.distortion)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"calibration values must be finite, got {values}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if len(self.distortion) not in _DISTORTION_LENGTHS:
            raise ValueError(f"distortion needs 4 or 5 coefficients (k1 k2 p1 p2 [k3]), got {len(self.distortion)}")

    @property
    def has_distortion(self) -> bool:
        return any(v != 0.0 for v in self.distortion)

    def as_array(self) -> np.ndarray:
        """``[fx, fy, cx, cy]`` as float64."""
        return np.array([self.fx, self.fy, self.cx, self.cy], dtype=np.float64)

    def camera_matrix(self) -> np.ndarray:
        """The 3×3 matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, src_hw: tuple[int, int], resized_hw: tuple[int, int], crop_hw: tuple[int, int] | None = None) -> "Calibration":
        """This calibration after resizing ``src_hw`` → ``resized_hw`` and centre-cropping to ``crop_hw``.

        Distortion coefficients are kept (they act on normalised coordinates).
        """
        k = resize_crop_intrinsics(self.as_array(), src_hw, resized_hw, crop_hw or resized_hw)
        return Calibration(*(float(v) for v in k), distortion=self.distortion)

    def prepared(self, src_hw: tuple[int, int], target_area: int = 384 * 512) -> "Calibration":
        """Intrinsics of the working image made by :class:`~droidw_cli.io.prepare.FramePreparer`.

        The preparer undistorts (keeping K) before resizing, so the result has
        no distortion.
        """
        resized, crop = working_size(src_hw[0], src_hw[1], target_area)
        k = resize_crop_intrinsics(self.as_array(), src_hw, resized, crop)
        return Calibration(*(float(v) for v in k))

    def validate(self, image_size: tuple[int, int], where: str = "calibration") -> "Calibration":
        """Check the principal point lies in an image of ``image_size`` = (H, W) and the focal lengths give
        a plausible field of view (:data:`FOCAL_RANGE`, :data:`MAX_ASPECT`); raise InputError if not."""
        h, w = image_size
        if not 0.0 <= self.cx <= w:
            raise InputError(f"{where}: cx={_fmt(self.cx)} is outside the {w}-pixel-wide image")
        if not 0.0 <= self.cy <= h:
            raise InputError(f"{where}: cy={_fmt(self.cy)} is outside the {h}-pixel-high image")
        side = max(h, w)
        for name, f in (("fx", self.fx), ("fy", self.fy)):
            if not FOCAL_RANGE[0] * side <= f <= FOCAL_RANGE[1] * side:
                fov = math.degrees(2.0 * math.atan(side / (2.0 * f)))
                raise InputError(f"{where}: {name}={_fmt(f)} px gives a {fov:.3g}° field of view across the "
                                 f"{side}-pixel side; expected {FOCAL_RANGE[0]:g}-{FOCAL_RANGE[1]:g} × {side} px "
                                 f"(is the calibration for another image size?)")
        if not 1.0 / MAX_ASPECT <= self.fx / self.fy <= MAX_ASPECT:
            raise InputError(f"{where}: fx={_fmt(self.fx)} and fy={_fmt(self.fy)} differ by more than {MAX_ASPECT:g}×")
        return self


def _fmt(v: float) -> str:
    return f"{v:g}"


def centre_principal_point(height: int, width: int) -> tuple[float, float]:
    """The image centre ``(cx, cy)`` under the pixel-centre convention: ((W − 1)/2, (H − 1)/2)."""
    return (width - 1) / 2.0, (height - 1) / 2.0


def default_calibration(height: int, width: int, focal_scale: float = 0.9) -> Calibration:
    """A starting guess for unknown intrinsics: f = focal_scale · max(H, W), centred principal point.

    Only an initial value; with ``--calib auto`` tracking refines the focal length.
    """
    f = focal_scale * max(height, width)
    cx, cy = centre_principal_point(height, width)
    return Calibration(f, f, cx, cy)


def from_values(values, where: str = "calibration", image_size: tuple[int, int] | None = None) -> Calibration:
    """Build a Calibration from ``fx fy cx cy [k1 k2 p1 p2 [k3]]`` with user-facing errors."""
    vals = [float(v) for v in values]
    if len(vals) not in (4, 8, 9):
        raise InputError(f"{where}: expected 4, 8 or 9 numbers (fx fy cx cy [k1 k2 p1 p2 [k3]]), got {len(vals)}")
    return _build(vals[:4], vals[4:], where, image_size)


def _build(k, dist, where: str, image_size: tuple[int, int] | None) -> Calibration:
    names = ("fx", "fy", "cx", "cy")
    for name, v in zip(names, k):
        if not math.isfinite(v):
            raise InputError(f"{where}: {name}={v} is not a finite number")
    for i, v in enumerate(dist):
        if not math.isfinite(v):
            raise InputError(f"{where}: distortion coefficient {i + 1} ({v}) is not a finite number")
    for name, v in zip(names[:2], k[:2]):
        if v <= 0:
            raise InputError(f"{where}: {name}={_fmt(v)} must be positive")
    if len(dist) not in _DISTORTION_LENGTHS:
        raise InputError(f"{where}: distortion needs 4 or 5 coefficients (k1 k2 p1 p2 [k3]), got {len(dist)}")
    calib = Calibration(*k, distortion=tuple(dist))
    if image_size is not None:
        calib.validate(image_size, where)
    return calib


def _parse_text(text: str, where: str) -> list[float]:
    lines = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines:
        raise InputError(f"{where}: the file holds no numbers")
    if len(lines) > 1:
        raise InputError(f"{where}: expected one line 'fx fy cx cy [k1 k2 p1 p2 [k3]]' (or YAML, or KITTI's "
                         f"P0: … lines), got {len(lines)} lines")
    out = []
    for tok in re.split(r"[,\s]+", lines[0].strip(", \t")):
        try:
            out.append(float(tok))
        except ValueError:
            raise InputError(f"{where}: {tok!r} is not a number") from None
    return out


def _number(value, key: str, where: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {key}={value!r} is not a number") from None


def _numbers(value, key: str, where: str) -> list[float]:
    if isinstance(value, dict) and "data" in value:  # OpenCV-style matrix node
        value = value["data"]
    if not isinstance(value, (list, tuple)):
        raise InputError(f"{where}: {key} must be a list of numbers")
    return [_number(v, key, where) for v in value]


def _parse_yaml(text: str, where: str) -> tuple[list[float], list[float]]:
    import yaml

    # OpenCV FileStorage headers ("%YAML:1.0") are not valid YAML directives.
    text = "\n".join(ln for ln in text.splitlines() if not ln.startswith("%YAML"))
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{where}: not valid YAML ({yaml_problem(exc)})") from None
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a YAML mapping with fx, fy, cx, cy or intrinsics")
    # "Camera.fx" / "Camera1.fx" (ORB-SLAM) → "fx"; keys are case-insensitive.
    flat = {re.sub(r"^camera\d*\.", "", str(k).lower()): v for k, v in data.items()}
    model = str(flat.get("distortion_model", "radial-tangential")).lower()
    if model not in _RADTAN_NAMES:
        raise InputError(f"{where}: distortion model {model!r} is not supported (only radial-tangential)")
    if "intrinsics" in flat:
        k = _numbers(flat["intrinsics"], "intrinsics", where)
        if len(k) != 4:
            raise InputError(f"{where}: intrinsics must be [fx, fy, cx, cy], got {len(k)} numbers")
    else:
        missing = [n for n in ("fx", "fy", "cx", "cy") if n not in flat]
        if missing:
            raise InputError(f"{where}: missing {', '.join(missing)} (or an 'intrinsics: [fx, fy, cx, cy]' list)")
        k = [_number(flat[n], n, where) for n in ("fx", "fy", "cx", "cy")]
    dist: list[float] = []
    for key in ("distortion", "distortion_coefficients", "dist_coeffs"):
        if flat.get(key) is not None:
            dist = _numbers(flat[key], key, where)
            break
    else:
        if all(n in flat for n in ("k1", "k2", "p1", "p2")):
            names = ("k1", "k2", "p1", "p2", "k3") if "k3" in flat else ("k1", "k2", "p1", "p2")
            dist = [_number(flat[n], n, where) for n in names]
    return k, dist


def _parse_kitti(text: str, where: str, camera: int) -> list[float]:
    """fx fy cx cy from the line ``P<camera>:`` of a KITTI calib.txt (see the module docstring)."""
    rows: dict[str, list[float]] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        name, sep, rest = s.partition(":")
        try:
            if not sep:
                raise ValueError
            rows[name.strip()] = [float(v) for v in rest.split()]
        except ValueError:
            raise InputError(f"{where}:{lineno}: expected 'NAME: numbers' as in KITTI's calib.txt, "
                             f"got {s[:60]!r}") from None
    key = f"P{camera}"
    if key not in rows:
        raise InputError(f"{where}: no {key} line (the projection matrix of camera {camera}, image_{camera})")
    if len(rows[key]) != 12:
        raise InputError(f"{where}: {key} needs 12 numbers (a 3×4 matrix, row-major), got {len(rows[key])}")
    p = np.array(rows[key]).reshape(3, 4)
    if not np.isfinite(p).all():
        raise InputError(f"{where}: {key} holds a value that is not a finite number")
    fx = p[0, 0]
    off = np.abs([p[0, 1], p[1, 0], p[2, 0], p[2, 1], p[2, 2] - 1.0]) * np.array([1.0, 1.0, fx, fx, fx])
    if not fx > 0 or off.max() > 1e-6 * fx:
        raise InputError(f"{where}: {key} is not a rectified pinhole projection [fx 0 cx *; 0 fy cy *; 0 0 1 *]")
    return [float(fx), float(p[1, 1]), float(p[0, 2]), float(p[1, 2])]


def load_calibration(path: str | Path, image_size: tuple[int, int] | None = None,
                     camera: int = 0) -> Calibration | None:
    """Read a calibration file (text, YAML or KITTI, see the module docstring).

    ``path == "auto"`` returns ``None``: tracking estimates the intrinsics.
    With ``image_size = (H, W)`` the principal point is checked to lie in the
    image.  ``camera`` picks the ``P<camera>`` line of a KITTI calib.txt (other
    formats hold one camera).  Every problem raises :class:`InputError`
    naming the file.
    """
    if isinstance(path, str) and path.strip().lower() == "auto":
        return None
    path = Path(path)
    where = f"calibration {path}"
    if not path.is_file():
        raise InputError(f"{where}: file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: cannot read ({exc})") from None
    if _KITTI_LINE.search(text):
        return _build(_parse_kitti(text, where, camera), [], where, image_size)
    is_yaml = path.suffix.lower() in _YAML_SUFFIXES or re.search(r"^\s*[A-Za-z_][\w.]*\s*:", text, re.M) is not None
    if is_yaml:
        k, dist = _parse_yaml(text, where)
        return _build(k, dist, where, image_size)
    return from_values(_parse_text(text, where), where, image_size)


def format_calibration(calib: Calibration) -> str:
    """The one-line text format, shortest round-trip float repr."""
    vals = (calib.fx, calib.fy, calib.cx, calib.cy, *calib.distortion)
    return " ".join(repr(float(v)) for v in vals) + "\n"


def write_calibration(path: str | Path, calib: Calibration) -> None:
    """Write ``fx fy cx cy [k1 k2 p1 p2 [k3]]`` atomically."""
    from droidw_cli.io.trajectory import atomic_write_text

    atomic_write_text(path, format_calibration(calib))
