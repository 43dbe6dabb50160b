"""droidw's CUDA backend for the uncertainty-aware BA.

Importing the package is cheap and safe on machines without CUDA: the kernels
(``csrc/``) are compiled with ``torch.utils.cpp_extension.load`` only when a
:class:`CudaBackend` first computes something, and cached under
``$TORCH_EXTENSIONS_DIR`` or ``~/.cache/droidw/torch_extensions``.
"""

from droidw_backend_cuda.backend import CudaBackend

__all__ = ["CudaBackend"]
