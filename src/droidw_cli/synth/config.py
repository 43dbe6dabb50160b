"""Parameters of a synthetic sequence (:class:`SynthConfig`) and one rendered frame (:class:`SynthFrame`).

Conventions
-----------
* World frame: x right, y into the room, z up (metres).  The room spans
  x ∈ [−W/2, W/2], y ∈ [0, D], z ∈ [0, H].
* Camera frame: OpenCV (x right, y down, z forward); ``pose_c2w`` maps camera
  coordinates to world coordinates, X_w = R X_c + t.
* Pixel centres sit at integer coordinates (see :mod:`droidw_cli.geometry.camera`),
  so the default principal point is ((W − 1)/2, (H − 1)/2).
* ``depth`` is the z-depth in metres (not the ray length): a pixel (u, v) with
  depth d back-projects to d · K⁻¹ [u, v, 1]ᵀ.
* Frame k has timestamp ``t0 + k / fps`` rounded to microseconds, the value
  written in the TUM files.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

#: bumped whenever one SynthConfig renders differently (files written before it existed count as 1)
GENERATOR_VERSION = 1
TUM_FOCAL_640 = 525.0  # the TUM RGB-D nominal focal length at 640×480
#: camera path families that travel down a street (synth.forward); their scene is a street (synth.street)
FORWARD_MOTIONS = ("forward", "ride", "drive")
#: follow shots in a street (synth.follow): the camera keeps one mover, the subject, in the middle of the frame
FOLLOW_MOTIONS = ("follow", "follow-pan")
STREET_MOTIONS = FORWARD_MOTIONS + FOLLOW_MOTIONS  # the camera paths whose scene is a street
#: camera path families, see synth.motions (new families go at the end: the room's draw from their index)
MOTIONS = ("handheld", "wobble", "rotate", "stopgo", "fixed") + FORWARD_MOTIONS + FOLLOW_MOTIONS


@dataclass(frozen=True)
class SynthConfig:
    """A synthetic room with a handheld camera and ``movers`` walking people.

    The same config gives byte-identical output.  Room, furniture, textures
    and the camera path depend only on ``seed`` (and the resolution, through
    the texel density), so ``static=True`` and the dynamic variant of one seed
    show the same room along the same path; movers are added on top (static
    pixels are identical).  The walkers' paths are tuned to the sequence
    (``frames``, ``fps``, speeds): the largest walker coverage of the image
    over the sequence is about ``target_coverage``.

    ``fx``/``fy``/``cx``/``cy`` default to the TUM focal length scaled to the
    width and the image centre.  ``texel_density`` (texels per metre)
    defaults to fx / 2, i.e. one texel per pixel at 2 m.  ``target_coverage``
    is the largest fraction of the image the movers cover at some frame: the
    closest mover's path is tuned to reach it (for 1-4 movers; more movers
    cover more).  ``camera_speed`` and ``mover_speed`` scale time for the
    camera path and the walkers (2.0 = twice the motion per frame).  ``noise_std`` adds Gaussian pixel noise
    (grey levels, 0-255 scale) to the colour images only.

    ``motion`` picks the camera path family (:data:`MOTIONS`, see
    :mod:`droidw_cli.synth.motions`): ``handheld`` (the default, a room-scale
    walk), ``wobble`` (near-still hand), ``rotate`` (fast roll/pitch/yaw on
    the spot), ``stopgo`` (the handheld path with full stops) or ``fixed``;
    ``forward``, ``ride`` and ``drive`` travel down a street
    (:mod:`droidw_cli.synth.forward`); ``follow`` and ``follow-pan`` are
    follow shots there, the camera panning to keep mover 0 (the subject)
    in the middle of the frame (:mod:`droidw_cli.synth.follow`).

    Photometric options (all off by default; they change the colour images
    only, never depth, mask or pose, which stay those of the frame's centre
    time), applied in this order:

    * ``blur``: motion blur over an exposure of ``blur`` frame intervals; up
      to ``blur_samples`` sub-frames (fewer when the image moves less) are
      averaged in linear intensity (see :mod:`droidw_cli.synth.exposure`);
    * ``gain_drift``: slow exposure gain 1 ± gain_drift, plus per-frame
      ``flicker`` (relative standard deviation);
    * ``noise_std`` as above;
    * ``jpeg_quality``: 1-100 passes the image through OpenCV JPEG (0 = off).

    ``grey``: the colour images become grey (ITU-R BT.601 luma in all three
    channels, after the photometric chain), as from a KITTI grey camera.

    ``apart`` (off by default, so the presets' scenes and figures stay as
    they were): walkers keep 0.7 m apart instead of walking through each
    other (:mod:`droidw_cli.synth.crowd`): the far walkers that would meet a
    walker before them are drawn again.
    """

    width: int = 640
    height: int = 480
    frames: int = 300
    fps: float = 30.0
    seed: int = 0
    movers: int = 3
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    noise_std: float = 0.0
    static: bool = False
    t0: float = 0.0
    texel_density: float | None = None
    target_coverage: float = 0.35
    camera_speed: float = 1.0
    mover_speed: float = 1.0
    depth_scale: float = 5000.0
    max_depth: float = 10.0
    motion: str = "handheld"
    blur: float = 0.0
    blur_samples: int = 7
    jpeg_quality: int = 0
    gain_drift: float = 0.0
    flicker: float = 0.0
    apart: bool = False
    grey: bool = False

    def __post_init__(self) -> None:
        if int(self.width) != self.width or int(self.height) != self.height or self.width < 16 or self.height < 16:
            raise ValueError(f"image size must be integers >= 16, got {self.width}x{self.height}")
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1, got {self.frames}")
        if not self.fps > 0:
            raise ValueError(f"fps must be positive, got {self.fps}")
        if self.movers < 0:
            raise ValueError(f"movers must be >= 0, got {self.movers}")
        if self.noise_std < 0:
            raise ValueError(f"noise_std must be >= 0, got {self.noise_std}")
        for name in ("fx", "fy", "texel_density"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ValueError(f"{name} must be positive, got {v}")
        if not 0.0 < self.target_coverage < 1.0:
            raise ValueError(f"target_coverage must be in (0, 1), got {self.target_coverage}")
        if self.camera_speed < 0 or self.mover_speed < 0:
            raise ValueError("camera_speed and mover_speed must be >= 0")
        if not (0 < self.depth_scale and 0 < self.max_depth and self.max_depth * self.depth_scale <= 65535):
            raise ValueError("need depth_scale > 0, max_depth > 0 and max_depth * depth_scale <= 65535 (16-bit PNG)")
        if self.motion not in MOTIONS:
            raise ValueError(f"unknown motion {self.motion!r} (use one of {', '.join(MOTIONS)})")
        if not 0.0 <= self.blur <= 1.0:
            raise ValueError(f"blur must be in [0, 1] (a fraction of the frame interval), got {self.blur}")
        if int(self.blur_samples) != self.blur_samples or self.blur_samples < 1:
            raise ValueError(f"blur_samples must be an integer >= 1, got {self.blur_samples}")
        if int(self.jpeg_quality) != self.jpeg_quality or not 0 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be an integer in [0, 100] (0 = off), got {self.jpeg_quality}")
        if not 0.0 <= self.gain_drift < 1.0 or not 0.0 <= self.flicker < 0.25:
            raise ValueError(f"need 0 <= gain_drift < 1 and 0 <= flicker < 0.25, got {self.gain_drift}, {self.flicker}")

    # -- derived values ---------------------------------------------------
    @property
    def n_movers(self) -> int:
        """The number of walkers actually rendered (0 when ``static``)."""
        return 0 if self.static else int(self.movers)

    @property
    def intrinsics(self) -> np.ndarray:
        """``[fx, fy, cx, cy]`` (float64) at the output resolution."""
        fx = self.fx if self.fx is not None else TUM_FOCAL_640 * self.width / 640.0
        fy = self.fy if self.fy is not None else fx
        cx = self.cx if self.cx is not None else (self.width - 1) / 2.0
        cy = self.cy if self.cy is not None else (self.height - 1) / 2.0
        return np.array([fx, fy, cx, cy], dtype=np.float64)

    @property
    def K(self) -> np.ndarray:
        """The 3×3 camera matrix."""
        fx, fy, cx, cy = self.intrinsics
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def rho(self) -> float:
        """Texel density in texels per metre: by default fx / 2 in a room (one texel a pixel at 2 m) and
        fx / 4 in a street (at 4 m: its surfaces are farther, and longer)."""
        if self.texel_density is not None:
            return float(self.texel_density)
        return float(self.intrinsics[0]) / (4.0 if self.motion in STREET_MOTIONS else 2.0)

    def timestamp(self, k: int) -> float:
        """Timestamp of frame ``k`` in seconds, rounded to microseconds as written in the files."""
        return round(self.t0 + k / self.fps, 6)

    # -- presets ----------------------------------------------------------
    @classmethod
    def preset(cls, name: str, **overrides) -> "SynthConfig":
        """A named configuration, with keyword overrides.

        ``static`` / ``dynamic`` / ``busy`` (no, 3 and 4 walkers; 640×480,
        300 frames) and ``*-small`` variants (320×240, 40 frames) for tests.
        Realistic 640×480 presets with blur, noise, JPEG and gain drift for the
        tracking benchmarks: ``walk`` (handheld, 2 walkers, 450 frames) and
        ``walk-static`` (the same room and path, no walkers), ``wobble``
        (near-still hand, a walker crossing close), ``rotate`` (fast rotation
        on the spot, 4 walkers), ``stopgo`` (handheld with full stops) and
        ``fixed`` (a still camera, 3 walkers, 300 frames).  Down a street:
        ``forward``, ``ride``, ``drive`` and ``forward-small``; follow shots
        ``follow`` (walking 2.5-4 m behind a walker, panning with it), its
        static control ``follow-static`` (the same path, nobody in the street)
        and ``follow-pan`` (walking slowly while panning side-on with a passer-by).
        """
        if name not in PRESETS:
            raise ValueError(f"unknown synth preset {name!r} (use one of {', '.join(sorted(PRESETS))})")
        return cls(**{**PRESETS[name], **overrides})

    def replace(self, **changes) -> "SynthConfig":
        return dataclasses.replace(self, **changes)


_SMALL = {"width": 320, "height": 240, "frames": 40}
PRESETS: dict[str, dict] = {
    "static": {"static": True, "movers": 0},
    "dynamic": {"movers": 3},
    "busy": {"movers": 4},
    "static-small": {"static": True, "movers": 0, **_SMALL},
    "dynamic-small": {"movers": 3, **_SMALL},
    "busy-small": {"movers": 4, **_SMALL},
}
_WALK = {"motion": "handheld", "movers": 2, "blur": 0.4, "jpeg_quality": 75, "noise_std": 1.5, "gain_drift": 0.08,
         "frames": 450}
PRESETS.update({
    "walk": _WALK,
    "walk-static": {**_WALK, "static": True, "movers": 0},
    "wobble": {"motion": "wobble", "movers": 2, "target_coverage": 0.45, "blur": 0.3, "jpeg_quality": 75,
               "noise_std": 1.5, "frames": 450},
    "rotate": {"motion": "rotate", "movers": 4, "blur": 0.5, "jpeg_quality": 60, "noise_std": 2.0, "gain_drift": 0.1,
               "frames": 450},
    "stopgo": {"motion": "stopgo", "movers": 2, "blur": 0.4, "jpeg_quality": 75, "frames": 450},
    "fixed": {"motion": "fixed", "movers": 3, "jpeg_quality": 75, "noise_std": 1.5, "frames": 300},
})
# forward motion down a street (synth.street_world): depth to 250 m in 16 bits at 1/256 m, as KITTI's depth maps
_STREET = {"depth_scale": 256.0, "max_depth": 250.0}
#: KITTI odometry's left grey camera (sequence 00, P0): 1241 × 376, fx = fy = 718.856
KITTI_CAMERA = {"width": 1241, "height": 376, "fx": 718.856, "fy": 718.856, "cx": 607.1928, "cy": 185.2157}
PRESETS.update({
    "forward": {**_STREET, "motion": "forward", "movers": 3, "blur": 0.4, "jpeg_quality": 75, "noise_std": 1.5,
                "gain_drift": 0.08, "frames": 450},
    "ride": {**_STREET, "motion": "ride", "movers": 2, "blur": 0.3, "jpeg_quality": 75, "noise_std": 1.5,
             "gain_drift": 0.05, "frames": 240},
    "drive": {**_STREET, **KITTI_CAMERA, "motion": "drive", "movers": 3, "fps": 10.0, "blur": 0.15, "noise_std": 2.0,
              "gain_drift": 0.05, "frames": 100, "texel_density": 90.0},
    "forward-small": {**_STREET, "motion": "forward", "movers": 2, **_SMALL},
})
# follow shots (synth.follow): mover 0 is the subject the camera keeps in the middle; blur, JPEG, noise as forward
_FOLLOW = {**_STREET, "movers": 3, "blur": 0.4, "jpeg_quality": 75, "noise_std": 1.5, "gain_drift": 0.08,
           "frames": 450}
PRESETS.update({
    "follow": {**_FOLLOW, "motion": "follow"},
    # its static control: the same path, the camera still aiming where the subject would be, nobody in the street
    "follow-static": {**_FOLLOW, "motion": "follow", "static": True},
    "follow-pan": {**_FOLLOW, "motion": "follow-pan", "blur": 0.5},
})


@dataclass(frozen=True, eq=False)
class SynthFrame:
    """One rendered frame with exact ground truth.

    ``rgb`` (H, W, 3) uint8 RGB; ``depth`` (H, W) float32 z-depth in metres;
    ``mask`` (H, W) bool, True where a walker is the nearest surface;
    ``pose_c2w`` (4, 4) float64 camera-to-world; ``index`` the frame number.
    """

    timestamp: float
    rgb: np.ndarray
    depth: np.ndarray
    mask: np.ndarray
    pose_c2w: np.ndarray
    index: int = 0
