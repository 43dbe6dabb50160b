"""droidw's reference uncertainty-aware BA backend: vectorised torch on the CPU."""

from droidw_backend_cpu.backend import CpuBackend

__all__ = ["CpuBackend"]
