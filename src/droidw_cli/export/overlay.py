"""Uncertainty overlays: a colour map of u over each keyframe, with a legend."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from droidw_cli.io.trajectory import atomic_write_bytes

LEGEND_WIDTH = 70


def _legend(height: int, lo: float, hi: float) -> np.ndarray:
    """A vertical colour bar (BGR) labelled from ``lo`` (bottom) to ``hi`` (top)."""
    bar = np.linspace(255, 0, height).astype(np.uint8)[:, None].repeat(18, 1)
    coloured = cv2.applyColorMap(bar, cv2.COLORMAP_INFERNO)
    panel = np.full((height, LEGEND_WIDTH, 3), 255, np.uint8)
    panel[:, 6:24] = coloured
    for frac in (0.0, 0.5, 1.0):
        y = int(round((1 - frac) * (height - 1)))
        y_text = min(max(y + 4, 10), height - 3)
        cv2.putText(panel, f"{lo + frac * (hi - lo):.2f}", (27, y_text), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1,
                    cv2.LINE_AA)
    cv2.putText(panel, "u", (10, 10 if height > 30 else height - 2), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1)
    return panel


def uncertainty_range(unc: np.ndarray) -> tuple[float, float]:
    """The colour map's range over a whole run: the 1st to the 99.5th percentile of u."""
    lo, hi = float(np.percentile(unc, 1)), float(np.percentile(unc, 99.5))
    return lo, max(hi, lo + 1e-3)


def blend(image_rgb: np.ndarray, uncertainty: np.ndarray, lo: float, hi: float, alpha: float = 0.55) -> np.ndarray:
    """BGR image: the keyframe with u (bilinearly upsampled, inferno colours) blended over it."""
    h, w = image_rgb.shape[:2]
    u = cv2.resize(uncertainty.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    norm = np.clip((u - lo) / max(hi - lo, 1e-6), 0, 1)
    heat = cv2.applyColorMap((norm * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)
    base = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)
    return cv2.addWeighted(base, 1 - alpha, heat, alpha, 0)


def overlay(image_rgb: np.ndarray, uncertainty: np.ndarray, lo: float, hi: float, alpha: float = 0.55) -> np.ndarray:
    """BGR image: :func:`blend` plus the legend."""
    blended = blend(image_rgb, uncertainty, lo, hi, alpha)
    return np.concatenate([blended, _legend(blended.shape[0], lo, hi)], axis=1)


def write_overlays(npz: dict, out_dir: Path, video: bool = False, scale: int = 2, fps: float = 5.0) -> list[Path]:
    """One PNG per keyframe (and optionally ``overlay.mp4``); returns the written paths."""
    if "uncertainty" not in npz:
        raise ValueError("this run has no uncertainty (it was tracked with uncertainty.enable=false)")
    unc = np.asarray(npz["uncertainty"], dtype=np.float32)
    images = np.asarray(npz["images"])
    index = np.asarray(npz["index"])
    lo, hi = uncertainty_range(unc)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths, frames = [], []
    for k in range(len(unc)):
        img = images[k]
        if scale != 1:
            img = cv2.resize(img, (img.shape[1] * scale, img.shape[0] * scale), interpolation=cv2.INTER_LINEAR)
        canvas = overlay(img, unc[k], lo, hi)
        ok, buf = cv2.imencode(".png", canvas)
        if not ok:
            raise OSError("PNG encoding failed")
        path = out_dir / f"uncertainty_{k:04d}_frame{int(index[k]):06d}.png"
        atomic_write_bytes(path, buf.tobytes())
        paths.append(path)
        if video:
            frames.append(canvas)
    if video and frames:
        h, w = frames[0].shape[:2]
        tmp = out_dir / ".overlay.tmp.mp4"
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        if not writer.isOpened():
            raise OSError("cannot open an mp4 writer (mp4v) in this OpenCV build")
        for f in frames:
            writer.write(f)
        writer.release()
        final = out_dir / "overlay.mp4"
        tmp.replace(final)
        paths.append(final)
    return paths
