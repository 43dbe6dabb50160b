"""The checks of an RGB-D run's input, before any tracking (``droidw track --depth``).

A run whose depth images are missing, empty or of the wrong size is a user error (exit 2, nothing
written); frames without a depth image, or a median depth no depth camera gives (a wrong
``--depth-scale``), are warnings.
"""

from __future__ import annotations

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.frames import decode_depth

#: depth images decoded by :func:`check_depth`, spread evenly over the selected frames
DEPTH_SAMPLES = 8


def open_depth(source, depth_scale: float) -> list[str]:
    """Prepare ``source`` for an RGB-D run: its depth scale, and mis-sized depth images as errors.

    Returns the warnings of :func:`check_depth`."""
    if not depth_scale > 0:
        raise InputError(f"--depth-scale must be positive, got {depth_scale:g}")
    if not getattr(source, "has_depth", False):
        raise InputError(f"{source.path}: RGB-D mode (--depth, config io.use_depth) needs depth images, and this "
                         f"input has none (a TUM/Bonn folder lists them in depth.txt)")
    notes = check_depth(source, depth_scale)
    source.depth_scale = float(depth_scale)
    source.strict_depth = True
    return notes


#: the median sensor depth (metres) outside which --depth-scale is probably wrong: nearer than depth cameras
#: measure, or farther than indoor RGB-D sensors reach
PLAUSIBLE_DEPTH = (0.2, 10.0)


def check_depth(source, depth_scale: float) -> list[str]:
    """Fail before the run when no frame has usable depth; warnings for frames without a depth image and
    for a median depth no depth camera gives (a wrong ``depth_scale``).

    A run whose every depth pixel is 0 (invalid) would have no metric scale yet be labelled metric.
    Sampled: up to :data:`DEPTH_SAMPLES` paired depth images, evenly over the selection; it is an
    error when none of them holds a non-zero pixel."""
    from droidw_cli.errors import InputError
    files = source.depth_files()
    paired = [p for p in files if p is not None]
    if not paired:
        raise InputError(f"{source.path}: none of the {len(files)} selected frames has a depth image "
                         f"(depth.txt lists none close enough to the frames' timestamps in rgb.txt)")
    notes = []
    if len(paired) < len(files):
        notes.append(f"{len(files) - len(paired)} of the {len(files)} selected frames have no depth image close "
                     f"to their timestamp; they are tracked without depth")
    picks = np.unique(np.round(np.linspace(0, len(paired) - 1, min(DEPTH_SAMPLES, len(paired)))).astype(int))
    medians = []
    for i in picks:
        raw = decode_depth(paired[i], depth_scale)
        if raw is not None and bool((raw > 0).any()):
            medians.append(float(np.median(raw[raw > 0])))
    if not medians:
        raise InputError(f"{source.path}: the depth images hold no depth: {len(picks)} of them, spread over the "
                         f"sequence (e.g. {paired[picks[0]].name}), are unreadable or 0 (invalid) everywhere; check "
                         f"the depth folder, or run without --depth")
    median = float(np.median(medians))
    lo, hi = PLAUSIBLE_DEPTH
    if not lo <= median <= hi:
        notes.append(f"the median sensor depth is {median:.3g} m with --depth-scale {depth_scale:g}, outside the "
                     f"{lo:g}-{hi:g} m depth cameras measure: check --depth-scale (5000: TUM, Bonn; 1000: millimetres)")
    return notes
