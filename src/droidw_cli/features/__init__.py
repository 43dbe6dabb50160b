"""Dense feature extractors (plugins): XFeat built in, others via the ``droidw.features`` entry points."""

from droidw_cli.features.base import FeatureExtractor
from droidw_cli.features.registry import ENTRY_POINT_GROUP, available_feature_extractors, get_feature_extractor

__all__ = ["FeatureExtractor", "get_feature_extractor", "available_feature_extractors", "ENTRY_POINT_GROUP"]
