"""The uncertainty-aware bundle adjustment: interface, parameters, registry."""

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet, UncertaintyStepResult

__all__ = ["BAParams", "UncertaintyParams", "BAState", "EdgeSet", "BAStepResult", "UncertaintyStepResult"]
