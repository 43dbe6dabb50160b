"""Run-time machinery around the SLAM algorithm: how it uses the machine, not what it computes.

* :mod:`~droidw_cli.runtime.heap`: glibc arenas, the mmap threshold inside global BA runs, trimming free pages.
* :mod:`~droidw_cli.runtime.slab`: many same-shaped tensors kept as the rows of one growable block.
* :mod:`~droidw_cli.runtime.threads`: torch's intra-op threads for the BA, usable cores.
* :mod:`~droidw_cli.runtime.timing`: wall time per pipeline stage.
* :mod:`~droidw_cli.runtime.prefetch`: a frame iterator run on a background thread, a few items ahead.
"""
