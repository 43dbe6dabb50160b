"""The C++ header of the BA's per-pixel maths, shared by the compiled backends.

``droidw_pixel.h`` holds the reprojection (Eq. 1), bilinear sampling, the
uncertainty weight factor (Eq. 5), the pose / focal / disparity Jacobian rows
and the similarity term (Eq. 7) as ``DROIDW_HD`` inline functions:
``__host__ __device__`` under nvcc, plain ``inline`` under g++.  The native CPU
backend (``backends/native``) and the CUDA kernels (``backends/cuda``) both
include it, so every CPU test run exercises the maths the CUDA kernels use.
"""

from pathlib import Path

#: the directory to put on a compiled backend's include path
INCLUDE_DIR = Path(__file__).resolve().parent
#: the shared header's file name
HEADER = "droidw_pixel.h"
