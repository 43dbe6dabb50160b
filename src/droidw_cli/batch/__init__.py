"""``droidw batch``: a manifest of sequences, tracked (and evaluated) one Ray task each."""

from droidw_cli.batch.manifest import ManifestError, Row, load_manifest
from droidw_cli.batch.runner import BatchOptions, ray_available, run_batch

__all__ = ["BatchOptions", "ManifestError", "Row", "load_manifest", "ray_available", "run_batch"]
