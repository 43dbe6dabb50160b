"""Trajectory evaluation, a thin layer over evo: association (``evo.core.sync``), Umeyama
alignment (``PoseTrajectory3D.align``), ATE / RPE (``evo.core.metrics``), plus droidw's
checks, error messages and reports.

The usual entry point is :func:`evaluate_ate`::

    from droidw_cli.eval import evaluate_ate
    result = evaluate_ate(gt, est, align="sim3", max_diff=0.02)
    print(result.rmse, result.scale)
"""

from droidw_cli.eval.align import ALIGN_MODES, DegenerateGeometryError, Sim3, align_positions, umeyama
from droidw_cli.eval.associate import Association, AssociationError, associate, associate_by_index
from droidw_cli.eval.metrics import (
    AteResult,
    ErrorStats,
    RpeResult,
    TooFewMatchesError,
    evaluate_ate,
    evaluate_rpe,
)

__all__ = [
    "ALIGN_MODES", "AssociationError", "Association", "AteResult", "DegenerateGeometryError", "ErrorStats",
    "RpeResult", "Sim3", "TooFewMatchesError", "align_positions", "associate", "associate_by_index",
    "evaluate_ate", "evaluate_rpe", "umeyama",
]
