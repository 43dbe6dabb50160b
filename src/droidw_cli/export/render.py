"""A point cloud drawn from a virtual camera into a PNG (no window, no OpenGL).

The scene's own frame comes from the keyframes: "up" is the mean of their
−y axes (OpenCV cameras look along +z with y down) and "ahead" the mean of
their +z axes, made orthogonal to up.  The virtual camera orbits the middle of
the cloud: ``azimuth`` degrees about up (0: from behind the mean
camera, looking the way it looked), ``elevation`` degrees above the
horizontal.  Its distance is chosen so that the central 90 % of the cloud
(monocular clouds have far outliers: disparities at their lower clamp) and
every keyframe position fit in the view at ``zoom`` 1.

Rasterisation is a z-buffer over splats: every point covers a
``point_size`` × ``point_size`` square, all squares are projected at once,
and per pixel the nearest one wins (one lexsort over (pixel, depth)).
Colours fade towards the background with depth (``depth_shading``), which is
what makes a still image of a cloud read as 3D.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from droidw_cli.io.trajectory import atomic_write_bytes

#: the view frames the points between this percentile and 100 minus it, on each axis
FRAME_PERCENTILE = 5.0
#: room left around the framed box
MARGIN = 1.1


@dataclass(frozen=True)
class RenderParams:
    """Image size (px), horizontal field of view and orbit angles (degrees), splat size (px),
    depth fading (0 = none, 1 = the farthest points vanish), background and trajectory colours (RGB)."""

    width: int = 640
    height: int = 480
    fov: float = 60.0
    azimuth: float = 0.0
    elevation: float = 25.0
    zoom: float = 1.0
    point_size: int = 2
    depth_shading: float = 0.5
    background: tuple[int, int, int] = (20, 20, 24)
    trajectory_colour: tuple[int, int, int] = (255, 170, 0)
    dynamic_colour: tuple[int, int, int] = (230, 40, 40)

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16:
            raise ValueError(f"image size must be at least 16x16, got {self.width}x{self.height}")
        if not 1.0 <= self.fov <= 170.0:
            raise ValueError(f"fov must be between 1 and 170 degrees, got {self.fov}")
        if not -89.0 <= self.elevation <= 89.0:
            raise ValueError(f"elevation must be between -89 and 89 degrees, got {self.elevation}")
        if self.zoom <= 0 or self.point_size < 1 or not 0.0 <= self.depth_shading <= 1.0:
            raise ValueError("zoom must be > 0, point_size ≥ 1 and depth_shading in [0, 1]")


@dataclass(frozen=True)
class View:
    """A pinhole camera: world-to-camera rotation (rows: camera x, y, z in world), its centre, focal (px)."""

    rotation: np.ndarray
    eye: np.ndarray
    focal: float
    width: int
    height: int

    def project(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(P, 3) world points → (P, 2) pixel coordinates and (P,) depths along the view axis."""
        cam = (np.asarray(xyz, np.float64) - self.eye) @ self.rotation.T
        z = cam[:, 2]
        zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
        uv = self.focal * cam[:, :2] / zs[:, None] + np.array([(self.width - 1) / 2, (self.height - 1) / 2])
        return uv, z


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def scene_axes(poses_c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(up, ahead), orthonormal world directions from the keyframes' mean orientation."""
    rot = np.asarray(poses_c2w, np.float64)[:, :3, :3]
    up = _unit(-rot[:, :, 1].mean(0))
    ahead = rot[:, :, 2].mean(0)
    ahead = ahead - (ahead @ up) * up
    if np.linalg.norm(ahead) < 1e-6:  # looking straight up or down: any horizontal direction
        ahead = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0])
    return up, _unit(ahead)


def look_at(xyz: np.ndarray, poses_c2w: np.ndarray, params: RenderParams) -> View:
    """The orbit camera of ``params``, aimed at the middle of ``xyz`` and the keyframe positions."""
    up, ahead = scene_axes(poses_c2w)
    centre = np.median(xyz, axis=0)
    az, el = np.radians(params.azimuth), np.radians(params.elevation)
    side = np.cross(ahead, up)
    horizontal = np.cos(az) * ahead + np.sin(az) * side
    forward = _unit(np.cos(el) * horizontal - np.sin(el) * up)  # looking down by el
    down = _unit(-up - (-up @ forward) * forward)
    rotation = np.stack([np.cross(down, forward), down, forward])
    rel = (xyz - centre) @ rotation.T
    cams = (np.asarray(poses_c2w, np.float64)[:, :3, 3] - centre) @ rotation.T
    lo = np.minimum(np.percentile(rel, FRAME_PERCENTILE, axis=0), cams.min(0))
    hi = np.maximum(np.percentile(rel, 100 - FRAME_PERCENTILE, axis=0), cams.max(0))
    centre = centre + rotation[:2].T @ ((lo[:2] + hi[:2]) / 2)  # aim at the middle of the framed box
    tan_x = np.tan(np.radians(params.fov) / 2)
    tan_y = tan_x * params.height / params.width
    need = MARGIN * max((hi[0] - lo[0]) / 2 / tan_x, (hi[1] - lo[1]) / 2 / tan_y, 1e-6)
    distance = (need - lo[2]) / params.zoom  # the nearest framed depth is still `need` away
    focal = (params.width - 1) / 2 / tan_x
    return View(rotation, centre - distance * forward, float(focal), params.width, params.height)


def rasterise(uv: np.ndarray, z: np.ndarray, rgb: np.ndarray, params: RenderParams) -> np.ndarray:
    """(H, W, 3) uint8 RGB: square splats, nearest first, faded with depth."""
    w, h, s = params.width, params.height, params.point_size
    image = np.empty((h * w, 3), np.uint8)
    image[:] = params.background
    front = z > 1e-6
    uv, z, rgb = uv[front], z[front], rgb[front]
    if len(z) == 0:
        return image.reshape(h, w, 3)
    offsets = np.stack(np.meshgrid(np.arange(s), np.arange(s), indexing="xy"), -1).reshape(-1, 2) - (s - 1) // 2
    pix = np.rint(uv)[:, None, :].astype(np.int64) + offsets[None]  # (P, s*s, 2)
    inside = (pix[..., 0] >= 0) & (pix[..., 0] < w) & (pix[..., 1] >= 0) & (pix[..., 1] < h)
    point = np.broadcast_to(np.arange(len(z))[:, None], inside.shape)[inside]
    flat = pix[..., 1][inside] * w + pix[..., 0][inside]
    order = np.lexsort((z[point], flat))
    first = np.ones(len(order), bool)
    first[1:] = flat[order][1:] != flat[order][:-1]
    win_pix, win_pt = flat[order][first], point[order][first]
    near, far = np.percentile(z, 2), np.percentile(z, 98)
    fade = params.depth_shading * np.clip((z[win_pt] - near) / max(far - near, 1e-9), 0.0, 1.0)
    bg = np.asarray(params.background, np.float64)
    image[win_pix] = np.rint(rgb[win_pt] * (1 - fade[:, None]) + bg * fade[:, None]).astype(np.uint8)
    return image.reshape(h, w, 3)


def render_cloud(xyz: np.ndarray, rgb: np.ndarray, poses_c2w: np.ndarray, params: RenderParams = RenderParams(),
                 dynamic: np.ndarray | None = None, trajectory: bool = True) -> np.ndarray:
    """(H, W, 3) uint8 RGB image of the cloud.

    Args:
        xyz, rgb: (P, 3) world points and their colours (uint8).
        poses_c2w: (K, 4, 4) keyframe poses: they set the scene's up and, with
            ``trajectory``, are drawn as a polyline over the points.
        dynamic: optional (P,) bool; those points are drawn in ``dynamic_colour``.
    """
    xyz = np.asarray(xyz, np.float64)
    if len(xyz) == 0:
        raise ValueError("the cloud has no points to render")
    colours = np.asarray(rgb, np.uint8).copy()
    if dynamic is not None:
        colours[np.asarray(dynamic, bool)] = params.dynamic_colour
    view = look_at(xyz, poses_c2w, params)
    uv, z = view.project(xyz)
    image = np.ascontiguousarray(rasterise(uv, z, colours, params))
    if trajectory and len(poses_c2w) > 1:
        cuv, cz = view.project(np.asarray(poses_c2w, np.float64)[:, :3, 3])
        path = np.rint(cuv[cz > 1e-6] * 16).astype(np.int32)  # 4 fractional bits for cv2's subpixel drawing
        cv2.polylines(image, [path.reshape(-1, 1, 2)], False, params.trajectory_colour, 2, cv2.LINE_AA, shift=4)
    return image


def write_png(path: str | Path, image_rgb: np.ndarray) -> None:
    """Write an RGB image as a PNG, atomically (maximum zlib compression)."""
    ok, data = cv2.imencode(".png", cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise ValueError(f"{path}: could not encode the image as PNG")
    atomic_write_bytes(path, data.tobytes())
