"""droidw: CPU-first dense SLAM for dynamic scenes (a DROID-W reimplementation)."""

__version__ = "0.1.0"
