"""3D Gaussian splatting on the CPU: the rasteriser, the static and temporal maps of ``droidw map``.

* :mod:`.model`: the Gaussians (position, log-scale, quaternion, opacity logit, SH degree-0 colour).
* :mod:`.camera`: a pinhole camera with a pose, and its crops and rescales.
* :mod:`.raster`: the rasteriser interface and the choice of an implementation (``auto``, ``torch``, ``gsplat``).
* :mod:`.torch_raster`: the pure-torch, differentiable CPU rasteriser; :mod:`.gsplat_raster`: gsplat on CUDA.
* :mod:`.ply`: the standard 3DGS PLY, written and read.
* :mod:`.losses`, :mod:`.inputs`, :mod:`.static_map`, :mod:`.dynamic_map`, :mod:`.heldout`, :mod:`.build`:
  the mapping of a tracked run (ADD-SLAM's static map and temporal object Gaussians).
"""
