"""Geometry on the BA grid: camera conventions, SE(3) helpers, dense reprojection and its Jacobians.

* :mod:`~droidw_cli.geometry.camera`: pixel-centre convention, intrinsics scaling.
* :mod:`~droidw_cli.geometry.lie`: pypose-layout SE(3) (``[t, q_xyzw]``), Exp with twists ``[v, ω]``.
* :mod:`~droidw_cli.geometry.poses`: the tracker's pose helpers (compose, invert, interpolate, to 4×4 matrices).
* :mod:`~droidw_cli.geometry.projection`: p_ij = Π(G_j G_i⁻¹ ∘ Π⁻¹(p_i, d_i)) and fused Jacobians.
* :mod:`~droidw_cli.geometry.sampling`: border-clamped bilinear sampling with explicit corner weights.
"""
