"""``droidw backends``: list the BA backends and whether they can run here."""

from __future__ import annotations

import json

import click


@click.command("backends")
@click.option("--build", is_flag=True, help="Also try to build/load compiled backends now (the CUDA and native kernels).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object per backend.")
def backends(build: bool, as_json: bool) -> None:
    """List the uncertainty-BA backends, whether each can run here, and why not.

    \b
    Example output:
      cpu: available (torch 2.13.0+cpu, 2 CPU threads)
      cuda: unavailable (no CUDA device)
      native: available (C++ kernels built at first use into ~/.cache/droidw/…, 2 CPU threads)
    """
    from droidw_cli.ba.registry import backend_info, backend_names, load_backend_class

    for name in backend_names():
        if build:
            try:
                ensure = getattr(load_backend_class(name), "ensure_built", None)
                if callable(ensure) and backend_info(name).available:
                    ensure(verbose=False)
            except Exception:  # the failure is recorded and shown as the reason below
                pass
        info = backend_info(name)
        if as_json:
            click.echo(json.dumps({"name": info.name, "available": info.available, "reason": info.reason}))
        else:
            status = "available" if info.available else "unavailable"
            click.echo(f"{info.name}: {status} ({info.reason})")
