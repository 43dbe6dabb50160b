"""Correspondence sources (plugins): dense targets p*_ij and confidences w_ij for frame-graph edges.

OpenCV DIS optical flow is built in (``dis``); others register under the
``droidw.correspondence`` entry-point group.
"""

from droidw_cli.correspondence.base import Correspondence, CorrespondenceSource
from droidw_cli.correspondence.dis import DISCorrespondence
from droidw_cli.correspondence.grid import flow_to_target, grid_coordinates, target_to_flow
from droidw_cli.correspondence.registry import (
    ENTRY_POINT_GROUP,
    available_correspondence_sources,
    get_correspondence_source,
)

__all__ = [
    "Correspondence",
    "CorrespondenceSource",
    "DISCorrespondence",
    "get_correspondence_source",
    "available_correspondence_sources",
    "flow_to_target",
    "target_to_flow",
    "grid_coordinates",
    "ENTRY_POINT_GROUP",
]
