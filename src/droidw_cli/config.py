"""Configuration: YAML files with ``inherit_from`` plus ``--set key=value``.

A config file is a mapping of sections (``io``, ``motion_filter``, ...) that
map one-to-one onto the frozen dataclasses below.  ``inherit_from: NAME``
(a file name relative to the including file, or a built-in config name)
loads a parent first; the child's keys override it section by section.
``--set frontend.window=30`` overrides one key, its value parsed as YAML.
An unknown key is an error naming the key and the file it came from.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.errors import ConfigError, yaml_problem

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"


@dataclass(frozen=True)
class IOConfig:
    """Frame preparation.  ``target_area``: pixels of the working image (384×512 by default)."""

    target_area: int = 384 * 512
    fps: float = 30.0
    stride: int = 1
    start: int = 0
    max_frames: int = 0  # 0 = all
    thumbnail_scale: int = 4  # keyframe thumbnails at 1/thumbnail_scale of the working size
    use_depth: bool = False  # RGB-D: sensor depth feeds the depth-prior term (rgbd.yaml)
    # frames decoded and prepared ahead on a thread (0: none).  4 left the main thread waiting 4-5 ms a frame (track_bench walk, default and fast config); 12 and 24: none
    prefetch: int = 16


@dataclass(frozen=True)
class CalibConfig:
    """Self-calibration for ``--calib auto`` (:mod:`droidw_cli.slam.focal`).

    BA starts from f₀ = ``focal_init`` · max(H, W).  The focal length stays fixed
    during initialisation and is optimised in a window BA only once the window
    spans ``min_keyframes`` keyframes whose orientations differ by at least
    ``min_rotation`` degrees (a translation alone leaves f unobservable: it
    trades against depth and the translation direction).  It is always kept in
    [``focal_min``, ``focal_max``] · f₀.
    """

    focal_init: float = 0.9
    min_keyframes: int = 8
    min_rotation: float = 5.0  # degrees
    focal_min: float = 0.3
    focal_max: float = 3.0

    def __post_init__(self) -> None:
        if not self.focal_init > 0:
            raise ValueError(f"calib.focal_init must be positive, got {self.focal_init}")
        if not 0 < self.focal_min <= 1 <= self.focal_max:
            raise ValueError(f"calib.focal_min/focal_max must satisfy 0 < min <= 1 <= max, "
                             f"got {self.focal_min}, {self.focal_max}")
        if self.min_keyframes < 2 or self.min_rotation < 0:
            raise ValueError("calib.min_keyframes must be >= 2 and calib.min_rotation >= 0")


#: Every flow threshold below is in pixels of the 1/8-resolution BA grid (DROID's unit): 3.0 grid px
#: is 24 px at a 384×512 working size, and the same value means the same motion at every working size.
GRID_UNIT = "px of the 1/8 grid"


@dataclass(frozen=True)
class MotionFilterConfig:
    """A frame is a keyframe candidate when the mean flow to the last keyframe ≥ ``thresh`` grid px.

    Before initialisation the *median* flow is tested, so a fixed camera watching movers (a minority of the pixels)
    never builds a map out of people walking by; after ``max_gap`` frames a lower flow quartile of ``init_min_quartile``
    grid px is enough (0 = never), so a near-still camera that only wobbles still gets keyframes every ``max_gap``
    frames instead of 30-40 frames apart.  With ``--calib auto`` (focal length estimated) the gap is ``max_gap_auto`` at most.
    """

    thresh: float = 3.0  # grid px
    max_gap: int = 13  # force a keyframe every max_gap frames (after initialisation); 9 until 2026-12-03 (docs/benchmarks.md)
    max_gap_auto: int = 9  # the focal length needs the views: 70-frame clip, f 0.2 % off at 9, 8 % at 11, 10.6 % at 13
    # grid px: the lower quartile of the flow from the first frame stays under 0.10 on the fixed preset (its median
    # reaches 0.63 when a walker fills the view) and 0.02 on vtest.avi; the near-still wobble's 0.9-1.4 after 7-10 frames
    init_min_quartile: float = 0.5

    def __post_init__(self) -> None:
        if self.thresh <= 0 or min(self.max_gap, self.max_gap_auto) < 1 or self.init_min_quartile < 0:
            raise ValueError("motion_filter.thresh must be > 0, max_gap and max_gap_auto >= 1, init_min_quartile >= 0")


@dataclass(frozen=True)
class CorrespondenceConfig:
    """The correspondence source (a plugin; ``dis`` = OpenCV DIS optical flow)."""

    name: str = "dis"
    preset: str = "medium"
    quick_preset: str = "fine"  # the filler's one-way flow keyframe → frame (quick_target)
    smoothness: float = 0.0  # DIS variational refinement α of the edges' flow (0: the preset's own, 20 for medium)
    coarsest_scale: int = 0  # DIS's coarsest level at least 1/2^k of the working size, by padding (correspondence/dis.py)
    fb_thresh: float = 1.0  # forward-backward consistency threshold, full-res px
    photo_sigma: float = 0.1  # photometric agreement scale (intensity in [0, 1])
    # px at the working resolution: no weight for pixels (or their targets) this close to the
    # image border, where DIS's flow is biased (correspondence/confidence.py)
    border_margin: float = 0.0


@dataclass(frozen=True)
class FeaturesConfig:
    """The dense feature extractor (a plugin; ``xfeat`` by default)."""

    name: str = "xfeat"
    half: bool = True  # store features as float16 in the keyframe buffer


@dataclass(frozen=True)
class FrontendConfig:
    """Initialisation and the sliding-window local BA (DROID-SLAM defaults; flows in grid px).

    Initialisation starts as soon as ``warmup_min`` keyframes show ``init_parallax`` grid px of parallax (the
    residual of keyframe 0 → newest flow after the best homography, which absorbs any rotation), or at
    ``warmup`` keyframes whatever the parallax (DROID's fixed count).  ``keyframe_thresh``: after the first
    ``iters1`` iterations, the second-newest keyframe is removed when its frame distance to the one before is
    below this (the camera slowed down or stopped), unless that would leave more than ``removal_max_span``
    frames between keyframes (the filler's motion-only BA loses accuracy over long gaps of slow but steady
    motion).  ``flow_thresh`` and ``nms``: proximity edges of the newest keyframes; ``proximity_max`` bounds how
    many new pairs one keyframe brings (one when it came under ``proximity_gap`` frames after the last).
    ``max_age``: an edge leaves the window BA after this many BA iterations.  ``robust_sigma`` > 0: every window
    BA step weights each correspondence by the Cauchy factor 1 / (1 + r²/σ²) of its current residual r (grid
    px), see :func:`droidw_cli.slam.optimizer.robust_edges`.
    """

    warmup: int = 12
    warmup_min: int = 3
    init_parallax: float = 0.15  # grid px
    init_iters: int = 40
    radius: int = 2
    window: int = 25
    window_span: int = 0  # frames: the window grows (to window_max keyframes) until it reaches this far back (Frontend._window_start)
    window_max: int = 35
    max_edges: int = 75
    flow_thresh: float = 16.0  # grid px
    keyframe_thresh: float = 3.0  # grid px
    removal_max_span: int = 12  # frames: no removal that would leave a longer gap between keyframes (600-frame walks, 3 seeds: mean ATE 0.85 cm at 12, 1.04 at 18)
    nms: int = 1
    proximity_max: int = 3
    proximity_gap: int = 4  # frames: a keyframe closer than this to its predecessor brings one proximity pair
    max_age: int = 50
    # frame distance d = beta · full motion + (1 − beta) · translation only (keyframe removal, proximity edges); 0.5 against
    # DROID-W's 0.75 took rotate from 29 % keyframes, 0.93 cm to 19 %, 0.82 cm, walk 0.64 → 0.53 cm (0.3: rotate 2.03 cm)
    beta: float = 0.5
    iters1: int = 3
    iters2: int = 2
    velocity_damping: float = 0.5
    place_iters: int = 4  # BA iterations placing a new keyframe against its predecessor (slam/placement.py)
    proximity_stride: int = 2  # the proximity candidates' frame distance averages every s-th grid pixel (s² cheaper)
    skip_doomed: bool = False  # pass over a candidate that removal would drop at once (Frontend.doomed): fast rotation
    match_ahead: bool = True  # match a new keyframe's pair (k, k − 1) on the prefetch thread, beside k − 1's BA (slam/scout.py)
    rotation_start: float = 4.0  # grid px: adjacent pairs start from the rotation alone below this rest (slam/starts.py)
    robust_sigma: float = 1.0  # grid px: Cauchy reweighting of the window BA's residuals (0 = off); rotate 2.82 → 1.07 cm with backend.robust_sigma 0.5

    def __post_init__(self) -> None:
        if self.robust_sigma < 0:
            raise ValueError(f"frontend.robust_sigma must be >= 0, got {self.robust_sigma}")
        if self.radius < 1 or self.window < self.radius + 1:
            raise ValueError(f"frontend.radius must be >= 1 and frontend.window > radius (a new keyframe's edges "
                             f"reach its {self.radius} predecessors inside the window), got window {self.window}, "
                             f"radius {self.radius}")
        if not 2 <= self.warmup_min <= self.warmup:
            raise ValueError(f"frontend.warmup_min must be >= 2 and <= warmup, got {self.warmup_min} and {self.warmup}")
        counts = {"iters1": self.iters1, "init_iters": self.init_iters, "max_edges": self.max_edges,
                  "max_age": self.max_age, "removal_max_span": self.removal_max_span,
                  "proximity_stride": self.proximity_stride}
        for name, value in counts.items():
            if value < 1:
                raise ValueError(f"frontend.{name} must be >= 1, got {value}")
        for name in ("iters2", "place_iters", "nms", "proximity_max", "proximity_gap", "keyframe_thresh", "init_parallax", "window_span", "rotation_start"):
            if getattr(self, name) < 0:
                raise ValueError(f"frontend.{name} must be >= 0, got {getattr(self, name)}")
        if not self.flow_thresh > 0:
            raise ValueError(f"frontend.flow_thresh must be > 0, got {self.flow_thresh}")
        for name in ("beta", "velocity_damping"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"frontend.{name} must be in [0, 1], got {getattr(self, name)}")


@dataclass(frozen=True)
class BackendConfig:
    """Global BA with proximity (loop) edges over the newest ``horizon`` keyframes
    (:mod:`droidw_cli.slam.backend`; flows in grid px).

    Proximity pairs: |i − j| > ``radius``, frame distance under ``thresh``,
    non-maximum suppression over ``nms`` keyframes, at most ``max_new`` per run.
    It runs every ``every`` new keyframes (``periodic_iters`` iterations; 0 =
    only at the end) and once at the end (``iters``).  Keyframes older than the
    horizon keep their poses and drop their edges and images.  ``robust_sigma`` > 0:
    Cauchy reweighting of the residuals as in :class:`FrontendConfig`.
    """

    enable: bool = True
    iters: int = 12
    thresh: float = 25.0  # grid px
    radius: int = 1
    nms: int = 5
    max_new: int = 32
    every: int = 20
    periodic_iters: int = 4
    horizon: int = 200
    image_quality: int = 95
    robust_sigma: float = 0.5  # grid px: Cauchy reweighting of the global BA's residuals (0 = off); rotate 1.21 → 1.07 cm against 1.0

    def __post_init__(self) -> None:
        if self.horizon < 3:
            raise ValueError(f"backend.horizon must be >= 3 keyframes, got {self.horizon}")
        if not 1 <= self.image_quality <= 100:
            raise ValueError(f"backend.image_quality must be in 1..100, got {self.image_quality}")
        if self.every < 0 or self.periodic_iters < 0 or self.iters < 0 or self.max_new < 0 or self.robust_sigma < 0:
            raise ValueError("backend.every, periodic_iters, iters, max_new and robust_sigma must be >= 0")


@dataclass(frozen=True)
class FillerConfig:
    """Poses for non-keyframes, online, from the motion filter's flow (:mod:`droidw_cli.slam.filler`).

    A gap's frames are solved once its anchor keyframe is ``lag`` keyframes old, by ``iters``
    motion-only IRLS iterations (Cauchy scale ``robust_sigma`` grid px).  With ρ the refined robust
    cost over the interpolation's, a frame takes the refined pose where ρ ≤ ``min_gain``, the
    interpolation where ρ ≥ ``blend_gain``, their geodesic blend between (a hard cut at ``min_gain``
    if ``blend_gain`` ≤ ``min_gain``); a refined camera centre that leaves the interpolated one by
    more than ``max_departure`` of the keyframe baseline is not used.  ``smooth``: passes of [1 2 1]/4 over the gap's departures.
    ``stride``: only every s-th frame of a gap is measured; the others take the departures interpolated in time.
    """

    iters: int = 3
    lag: int = 2
    robust_sigma: float = 0.25  # grid px
    min_gain: float = 0.4  # cost ratio at and below which the refined pose is taken whole
    blend_gain: float = 0.8  # cost ratio at and above which the interpolation is kept
    uncertainty: bool = True  # weight the keyframes' pixels by their uncertainty
    # share of the baseline (0: any).  Wobble (1-2.5 cm failed refinements): 0.5: 0.36 → 0.33 cm mono, 0.61 → 0.39 RGB-D (SE(3)); the rest within 0.01 cm
    max_departure: float = 0.5
    smooth: int = 1  # passes (0: off); docs/benchmarks.md "What the filler adds to the error"
    stride: int = 1

    def __post_init__(self) -> None:
        if min(self.min_gain, self.blend_gain, self.max_departure, self.smooth) < 0 or self.robust_sigma <= 0 or self.stride < 1:
            raise ValueError("filler.min_gain, blend_gain, max_departure, smooth must be >= 0, robust_sigma > 0, stride >= 1")


#: the dynamic-mask modes of ``dynamics.mode``
DYNAMICS_MODES = ("epipolar", "consistency", "both", "none")


@dataclass(frozen=True)
class DynamicsConfig:
    """Explicit dynamic masks (:mod:`droidw_cli.dynamics`); the learned uncertainty is independent of them.

    ``mode`` chooses the masks whose pixels get zero correspondence confidence in BA:

    * ``epipolar`` (with ``uncertainty.enable``): the pixels of a keyframe that the
      dominant epipolar geometry of its edges cannot explain
      (:mod:`droidw_cli.dynamics.epipolar`): Sampson distance above
      ``epipolar_thresh`` working-resolution px on any edge, grown by
      ``epipolar_dilate`` grid cells (``epipolar_in_view``: cells map or flow keep in view only).  Off while
      the focal length is estimated (``--calib auto``): on a real clip they took it from 617 px to 17 px.
    * ``consistency``: ADD-SLAM scene consistency (:mod:`droidw_cli.dynamics.inloop`):
      each new keyframe's colour and depth are predicted from its
      ``consistency_sources`` predecessors through the current poses and depths
      (the sensor depth in RGB-D mode); pixels above ``tau_scale`` × the median
      error that are nearer than predicted are seeds, grown to whole objects by
      the ``segmenter`` plugin (``grow``: the built-in region grower).
    * ``both``: the union; ``none``: no masks.

    Object ids across keyframes follow the overlap of each object's predicted
    mask (:mod:`droidw_cli.dynamics.tracker`); ADD-SLAM's rules guard the weak
    matches by centre alone (area growth at most ``track_growth``×, centre jump
    at most ``track_jump`` of the width), and no new object starts within
    ``track_border`` of the image border or with less than ``track_min_new`` of the view.
    ``track_backtrack``: after the run, each new object is carried back through the keyframes
    before its birth (:mod:`droidw_cli.dynamics.backtrack`, ADD-SLAM's backtracking).
    """

    mode: str = "epipolar"
    epipolar_thresh: float = 0.5
    epipolar_dilate: int = 2
    epipolar_in_view: bool = True
    tau_scale: float = 20.0
    consistency_sources: int = 3
    segmenter: str = "grow"
    track_border: float = 0.04
    track_growth: float = 1.5
    track_jump: float = 0.2
    # a component unclaimed by any track starts a new object only above this share of the view (the
    # tracker's own default is 0.01).  Replayed on the captured finish() inputs of the 8 preset runs of
    # `dynamic_bench.py --modes` at seeds 1 and 2: id switches of the worst walker summed 54 → 49 at 0.02
    # (5 sequences fewer, none more; 0.03: 48), walkers in view with an id 95.6 → 95.4 %, ids shared unchanged
    track_min_new: float = 0.02
    # replayed as above: walkers in view with an id 95.4 → 96.3 %, id switches summed 49 either way
    track_backtrack: bool = True

    def __post_init__(self) -> None:
        if self.mode not in DYNAMICS_MODES:
            raise ValueError(f"dynamics.mode must be one of {', '.join(DYNAMICS_MODES)}, got {self.mode!r}")
        if not self.tau_scale > 0:
            raise ValueError(f"dynamics.tau_scale must be positive, got {self.tau_scale}")
        if self.consistency_sources < 1:
            raise ValueError(f"dynamics.consistency_sources must be >= 1, got {self.consistency_sources}")
        if not 0 <= self.track_min_new < 1:
            raise ValueError(f"dynamics.track_min_new must be in [0, 1), got {self.track_min_new}")

    @property
    def epipolar(self) -> bool:
        """Whether the epipolar masks are on (``epipolar`` or ``both``)."""
        return self.mode in ("epipolar", "both")

    @property
    def consistency(self) -> bool:
        """Whether the scene-consistency masks are on (``consistency`` or ``both``)."""
        return self.mode in ("consistency", "both")


@dataclass(frozen=True)
class TrackConfig:
    """Everything ``droidw track`` needs.  ``ba.uncertainty`` mirrors ``uncertainty``."""

    io: IOConfig = field(default_factory=IOConfig)
    calib: CalibConfig = field(default_factory=CalibConfig)
    motion_filter: MotionFilterConfig = field(default_factory=MotionFilterConfig)
    correspondence: CorrespondenceConfig = field(default_factory=CorrespondenceConfig)
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)
    filler: FillerConfig = field(default_factory=FillerConfig)
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)
    ba: BAParams = field(default_factory=BAParams)
    seed: int = 0
    # torch intra-op threads of the BA; 0: one less than the usable cores (1 on 2 cores, at most 8), all in the global BA.
    # On 2 cores, 2 torch threads stall whenever anything else runs (ba_step 25/75: 852 ms against
    # 20 ms with 1 thread while other processes were busy), and the prefetch thread and DIS need a core.
    threads: int = 0

    def __post_init__(self) -> None:
        if self.threads < 0:
            raise ValueError(f"threads must be >= 0 (0: one less than the usable cores), got {self.threads}")
        # The uncertainty section is the single source of truth for the BA's copy.
        object.__setattr__(self, "ba", dataclasses.replace(self.ba, uncertainty=self.uncertainty))
        if self.backend.horizon < self.frontend.window:  # the window (and window_max) stays inside the horizon
            raise ValueError("backend.horizon must be >= frontend.window: the window BA needs its keyframes' features")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["ba"].pop("uncertainty", None)
        return d


# Keys of nested dataclasses that a config file may not set directly.
_HIDDEN = {(BAParams, "uncertainty")}


def _resolve_type(tp: Any) -> Any:
    if isinstance(tp, str):
        return eval(tp, vars(typing) | vars(types))  # noqa: S307 - annotations of our own dataclasses
    return tp


def _coerce(value: Any, tp: Any, key: str, source: str) -> Any:
    tp = _resolve_type(tp)
    if tp is Any:
        return value
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{source}: {key} must be true or false, got {value!r}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str):  # YAML 1.1 reads "1e-6" (no dot) as a string
            try:
                number = float(value)
            except ValueError:
                number = math.nan
            if math.isfinite(number):  # not "nan" / "inf" spelt out
                return number
        raise ConfigError(f"{source}: {key} must be a number, got {value!r}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{source}: {key} must be an integer, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{source}: {key} must be a string, got {value!r}")
    return value


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _build(cls: type, data: dict, sources: dict[str, str], prefix: str = "") -> Any:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if (cls, f.name) not in _HIDDEN}
    kwargs = {}
    for key, value in data.items():
        full = f"{prefix}{key}"
        source = sources.get(full, sources.get(prefix.rstrip("."), "config"))
        if key not in names:
            raise ConfigError(f"{source}: unknown config key '{full}' (valid keys here: {', '.join(sorted(names))})")
        tp = hints[key]
        if dataclasses.is_dataclass(tp):
            if not isinstance(value, dict):
                raise ConfigError(f"{source}: '{full}' must be a mapping")
            kwargs[key] = _build(tp, value, sources, full + ".")
        else:
            kwargs[key] = _coerce(value, tp, full, source)
    try:
        return cls(**kwargs)
    except ValueError as exc:
        raise ConfigError(f"{sources.get(prefix.rstrip('.'), 'config')}: {exc}") from None


def _record_sources(data: dict, source: str, sources: dict[str, str], prefix: str = "") -> None:
    for k, v in data.items():
        sources[f"{prefix}{k}"] = source
        if isinstance(v, dict):
            _record_sources(v, source, sources, f"{prefix}{k}.")


def find_config(name_or_path: str | Path, relative_to: Path | None = None) -> Path:
    """A config path from a file path or a built-in name (``default``, ``tum`` ...)."""
    p = Path(name_or_path)
    candidates = [p]
    if relative_to is not None:
        candidates.append(relative_to / p)
    candidates += [CONFIG_DIR / p, CONFIG_DIR / f"{p}.yaml"]
    for c in candidates:
        if c.is_file():
            return c
    builtin = ", ".join(sorted(x.stem for x in CONFIG_DIR.glob("*.yaml"))) if CONFIG_DIR.is_dir() else "none"
    raise ConfigError(f"config '{name_or_path}' not found (built-in configs: {builtin})")


def _load_tree(path: Path, sources: dict[str, str], seen: tuple[Path, ...] = ()) -> dict:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{path}: inherit_from forms a cycle")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML ({yaml_problem(exc)})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a config file must be a mapping of sections")
    parent_name = data.pop("inherit_from", None)
    base: dict = {}
    if parent_name:
        base = _load_tree(find_config(parent_name, path.parent), sources, seen + (path,))
    _record_sources(data, str(path), sources)
    return _merge(base, data)


def parse_overrides(overrides: list[str] | tuple[str, ...]) -> dict:
    """``["a.b=1", "c.d=x"]`` → nested dict, values parsed as YAML scalars."""
    out: dict = {}
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected key.sub=value")
        key, raw = item.split("=", 1)
        key = key.strip()
        if not key:
            raise ConfigError(f"--set {item!r}: empty key")
        try:
            value = yaml.safe_load(raw) if raw.strip() else ""
        except yaml.YAMLError:
            value = raw
        node = out
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


def load_config(name_or_path: str | Path = "default", overrides: list[str] | tuple[str, ...] = ()) -> TrackConfig:
    """Load a config (with inheritance) and apply ``--set`` overrides."""
    sources: dict[str, str] = {}
    data = _load_tree(find_config(name_or_path), sources)
    over = parse_overrides(overrides)
    _record_sources(over, "--set", sources)
    return _build(TrackConfig, _merge(data, over), sources)
