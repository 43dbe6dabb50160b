"""droidw's native CPU backend for the uncertainty-aware BA (C++ kernels, ``torch.utils.cpp_extension``).

Importing the package is cheap and needs no compiler: the kernels (``csrc/``)
are built when a :class:`NativeBackend` is first started, cached under
``$TORCH_EXTENSIONS_DIR`` or ``~/.cache/droidw/torch_extensions``, and where
they cannot be built the registry runs the ``cpu`` backend instead.
"""

from droidw_backend_native.backend import NativeBackend

__all__ = ["NativeBackend"]
