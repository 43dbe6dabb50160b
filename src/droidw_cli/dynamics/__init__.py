"""Category-agnostic dynamic detection by scene consistency (ADD-SLAM style).

Pipeline for one keyframe (pure functions, torch over pixels):

* :func:`predict_views` — backward-warp neighbours' colour and depth into it;
* :func:`inconsistency` — colour/depth error maps, τ = tau_scale × median,
  the signed-depth rule M_ic^d = M_ic ∩ (D − D̂ < 0), views combined;
* :func:`refine_mask` — region growing of the seeds, inscribed-circle centres;
* :func:`detect_dynamic` — all of the above for every keyframe;
* :class:`DynamicObjectTracker` — object ids across frames.

:mod:`droidw_cli.dynamics.epipolar` is a cheaper cue that needs no map that the
tracker uses: pixels off the dominant epipolar geometry of the dense flow.
"""

from droidw_cli.dynamics.consistency import InconsistencyMaps, inconsistency
from droidw_cli.dynamics.detect import FrameDetection, detect_dynamic, detect_frame, neighbour_sources
from droidw_cli.dynamics.params import DetectionParams
from droidw_cli.dynamics.refine import (Objects, grow_regions, inscribed_centres, label_components, make_objects,
                                        refine_mask)
from droidw_cli.dynamics.tracker import DynamicObjectTracker, TrackedObject, TrackEnd
from droidw_cli.dynamics.warp import predict_views

__all__ = [
    "DetectionParams", "DynamicObjectTracker", "FrameDetection", "InconsistencyMaps", "Objects", "TrackEnd",
    "TrackedObject", "detect_dynamic", "detect_frame", "grow_regions", "inscribed_centres", "inconsistency",
    "label_components", "make_objects", "neighbour_sources", "predict_views", "refine_mask",
]
