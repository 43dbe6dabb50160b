"""BA settings that the CUDA tests compare against the CPU backend (shared by the glue and parity tests)."""

from __future__ import annotations

from droidw_cli.ba.params import BAParams, UncertaintyParams

BA_STEP_CASES = [
    BAParams(uncertainty=UncertaintyParams(enable=False)),
    BAParams(),
    BAParams(uncertainty=UncertaintyParams(mode="inverse", bidirectional=True)),
    BAParams(motion_only=True),
    BAParams(optimize_focal="shared"),
    BAParams(optimize_focal="xy", t0=2),
]
