"""The uncertainty-aware bundle adjustment: interface, parameters, registry.

* :mod:`~droidw_cli.ba.types` / :mod:`~droidw_cli.ba.params`: the typed inputs, outputs and settings.
* :mod:`~droidw_cli.ba.interface`: :class:`BABackend` and ``validate_inputs``.
* :mod:`~droidw_cli.ba.registry`: ``get_backend('auto'|'cpu'|'cuda')``, ``resolve_backend`` (which one
  ``auto`` picked, and why), ``list_backends()``.
* :mod:`~droidw_cli.ba.schur`: block-sparse Schur complement and the GN update (shared by backends).
* :mod:`~droidw_cli.ba.uncertainty`: u = softplus(θ·F + b), BA weight factors, the θ objective.
* :mod:`~droidw_cli.ba.synthetic`: synthetic problems with ground truth (tests, benchmarks).
"""

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet, UncertaintyStepResult

__all__ = ["BAParams", "UncertaintyParams", "BAState", "EdgeSet", "BAStepResult", "UncertaintyStepResult"]
