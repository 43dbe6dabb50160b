"""Thin click entry points; the work happens in the core packages."""
