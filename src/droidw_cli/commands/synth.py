"""``droidw synth``: write a synthetic dynamic-scene sequence with exact ground truth."""

from __future__ import annotations

import re
import time

import click

from droidw_cli.errors import UserError
from droidw_cli.synth.config import MOTIONS, PRESETS


def _parse_size(ctx, param, value: str | None) -> tuple[int, int] | None:
    if value is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", value)
    if not m:
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 640x480, got {value!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if w < 16 or h < 16 or w > 8192 or h > 8192:
        raise click.BadParameter(f"size must be between 16 and 8192 pixels a side, got {w}x{h}")
    return w, h


@click.command("synth")
@click.argument("out_dir", type=click.Path(file_okay=False, writable=True))
@click.option("--preset", default="dynamic", show_default=True, type=click.Choice(list(PRESETS)),
              help="Starting configuration; the options below override it.")
@click.option("--frames", type=click.IntRange(min=1), default=None, help="Number of frames [preset: 300].")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Random seed; the same seed gives identical files.")
@click.option("--movers", type=click.IntRange(min=0), default=None, help="Number of walking people [preset: 3].")
@click.option("--size", callback=_parse_size, default=None, metavar="WxH", help="Image size [preset: 640x480].")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=None, help="Frame rate [30].")
@click.option("--noise", type=click.FloatRange(min=0), default=None, help="Gaussian pixel noise std, grey levels [0].")
@click.option("--motion", type=click.Choice(list(MOTIONS)), default=None,
              help="Camera path: handheld walk, near-still wobble, fast rotate, stopgo, fixed; down a street: "
                   "forward, ride, drive, follow, follow-pan [handheld].")
@click.option("--blur", type=click.FloatRange(0, 1), default=None,
              help="Motion blur: exposure as a fraction of the frame interval, e.g. 0.5 [0 = off].")
@click.option("--jpeg", type=click.IntRange(0, 100), default=None, help="JPEG quality of the colour images [0 = off].")
@click.option("--gain-drift", type=click.FloatRange(0, 1, max_open=True), default=None,
              help="Slow exposure gain change, e.g. 0.1 = ±10 % [0].")
@click.option("--static", "static", is_flag=True, help="No movers: a static scene.")
@click.option("--apart", is_flag=True, help="Walkers keep 0.7 m apart (by default they may walk through each other).")
@click.option("--layout", type=click.Choice(["tum", "kitti"]), default="tum", show_default=True,
              help="Folder layout: TUM RGB-D (rgb.txt, groundtruth.txt) or KITTI odometry (image_0/ or image_2/, "
                   "times.txt, calib.txt, poses.txt).")
@click.option("--grey", is_flag=True, help="Grey images (luma); the KITTI layout writes them to image_0/.")
@click.option("--video", is_flag=True, help="Also write video.mp4 (video.avi if mp4v is unavailable).")
@click.option("--overwrite", is_flag=True, help="Replace OUT_DIR if it exists and is not empty.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
def synth(out_dir: str, preset: str, frames: int | None, seed: int, movers: int | None, size, fps: float | None,
          noise: float | None, motion: str | None, blur: float | None, jpeg: int | None, gain_drift: float | None,
          static: bool, apart: bool, layout: str, grey: bool, video: bool, overwrite: bool, quiet: bool) -> None:
    """Generate a synthetic room with walking people and write it as a TUM-style (or KITTI) folder.

    \b
    OUT_DIR gets rgb/, depth/ (16-bit, ×5000), mask/ (255 = moving), rgb.txt,
    depth.txt, groundtruth.txt (camera-to-world, TUM), calib.txt (fx fy cx cy).
    With --layout kitti: image_0/ (--grey) or image_2/, depth/, mask/,
    times.txt, calib.txt (P0-P3), poses.txt (KITTI, relative to frame 0).
    Presets walk, walk-static, wobble, rotate, stopgo and fixed add camera
    motions, motion blur, noise, JPEG and gain drift (realistic 640x480);
    forward, ride and drive travel down a street with walkers and cars (a
    walk, a bike ride, and a car at 10 frames/s with KITTI's 1241x376 camera);
    follow and follow-pan are follow shots there: the camera pans to keep one
    walker (mover 0) in the middle of the frame while the street streams past
    (walking 2.5-4 m behind it, or side-on as it overtakes).
    Examples:
      droidw synth seq/ --frames 300 --movers 3 --video
      droidw synth seq/ --preset rotate --blur 0.3
      droidw synth seq-kitti/ --preset drive --layout kitti --grey
      droidw synth seq-follow/ --preset follow --seed 1
    """
    from droidw_cli.synth import SynthConfig, write_sequence

    overrides: dict = {"seed": seed}
    if frames is not None:
        overrides["frames"] = frames
    if movers is not None:
        overrides["movers"] = movers
    if size is not None:
        overrides["width"], overrides["height"] = size
    if fps is not None:
        overrides["fps"] = fps
    for key, value in (("noise_std", noise), ("motion", motion), ("blur", blur), ("jpeg_quality", jpeg),
                       ("gain_drift", gain_drift)):
        if value is not None:
            overrides[key] = value
    if apart:
        overrides["apart"] = True
    if grey:
        overrides["grey"] = True
    if static:
        overrides["static"] = True
    elif movers:
        overrides["static"] = False  # asking for movers overrides a static preset
    try:
        cfg = SynthConfig.preset(preset, **overrides)
    except ValueError as exc:
        raise UserError(f"synth: {exc}") from None
    start = time.perf_counter()
    path = write_sequence(cfg, out_dir, video=video, progress=not quiet, overwrite=overwrite, layout=layout)
    elapsed = time.perf_counter() - start
    if not quiet:
        click.echo(f"wrote {cfg.frames} frames ({cfg.width}x{cfg.height}, {cfg.n_movers} movers, {cfg.motion} camera, "
                   f"seed {cfg.seed}) to {path} in {elapsed:.1f} s ({cfg.frames / max(elapsed, 1e-9):.1f} frames/s)")
