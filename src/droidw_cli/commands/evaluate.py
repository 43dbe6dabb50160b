"""``droidw eval``: ATE (and optionally RPE) of a trajectory against ground truth."""

from __future__ import annotations

import json

import click

FORMAT_CHOICES = click.Choice(["auto", "tum", "kitti", "euroc"], case_sensitive=False)


@click.command("eval")
@click.option("--gt", "gt_path", required=True, metavar="FILE", help="Ground-truth trajectory (TUM, KITTI or EuRoC CSV).")
@click.option("--est", "est_path", default="traj.txt", show_default=True, metavar="FILE|RUN",
              help="Estimated trajectory, or a run folder containing traj.txt.")
@click.option("--align", type=click.Choice(["sim3", "se3", "none"]), default="sim3", show_default=True,
              help="Umeyama alignment before measuring: sim3 (with scale, for monocular runs), se3 (for metric "
                   "RGB-D runs, `track --depth`: run.json says \"metric\": true) or none.")
@click.option("--max-diff", type=click.FloatRange(min=0.0), default=0.02, show_default=True, metavar="SECONDS",
              help="Largest timestamp difference for associating poses (nearest timestamp).")
@click.option("--t-offset", type=float, default=0.0, show_default=True, metavar="SECONDS",
              help="Offset added to the estimate's timestamps before associating.")
@click.option("--format", "fmt", type=FORMAT_CHOICES, default="auto", show_default=True,
              help="Format of the estimate (and of the ground truth unless --gt-format is given).")
@click.option("--gt-format", type=FORMAT_CHOICES, default=None, help="Format of the ground truth.")
@click.option("--gt-times", type=str, default=None, metavar="FILE",
              help="Timestamps for a KITTI ground truth [default, against a timestamped estimate: times.txt in "
                   "its folder, if any].")
@click.option("--est-times", type=str, default=None, metavar="FILE",
              help="Timestamps for a KITTI estimate [default, against a timestamped ground truth: times.txt in "
                   "its folder, if any].")
@click.option("--rpe", "rpe_delta", type=click.IntRange(min=1), default=None, metavar="DELTA",
              help="Also report the translational RPE over pose pairs DELTA matched frames apart.")
@click.option("--plot", "plot_path", type=str, default=None, metavar="PNG",
              help="Write evo's top view of both trajectories after alignment, the estimate coloured by its error.")
@click.option("--save-results", "results_path", type=str, default=None, metavar="FILE.zip",
              help="Write the ATE in evo's result format, for `evo_res` to compare with other systems.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of the table.")
def evaluate(gt_path: str, est_path: str, align: str, max_diff: float, t_offset: float, fmt: str,
             gt_format: str | None, gt_times: str | None, est_times: str | None, rpe_delta: int | None,
             plot_path: str | None, results_path: str | None, as_json: bool) -> None:
    """Evaluate an estimated trajectory against ground truth: ATE after Umeyama alignment.

    The association, alignment and metrics are evo's (the same numbers as
    `evo_ape tum GT EST -a [-s]`).  KITTI files carry no timestamps: two KITTI
    files are paired by index, or give --gt-times / --est-times; a KITTI file
    compared with a timestamped one takes times.txt from its own folder (as
    `droidw synth --layout kitti` writes it).

    \b
    Examples:
      droidw eval --gt groundtruth.txt --est run/
      droidw eval --gt gt.csv --est traj.txt --align se3 --rpe 10 --plot top.png
      droidw eval --gt KITTI_00_gt.txt --est KITTI_00_ORB.txt --json
      droidw eval --gt seq-kitti/poses.txt --est run/
      droidw eval --gt groundtruth.txt --est run/ --save-results droidw.zip && evo_res droidw.zip other.zip
    """
    from droidw_cli.eval import inputs
    from droidw_cli.eval.metrics import evaluate_ate, evaluate_rpe
    from droidw_cli.eval.report import EvalInfo, format_text, plot_top_view, save_results, to_json_dict
    from droidw_cli.io.outputs import check_output_file

    for path in (plot_path, results_path):
        if path is not None:
            check_output_file(path)
    fmt = fmt.lower()
    gt = inputs.load(gt_path, (gt_format or fmt).lower(), gt_times, role="gt")
    est = inputs.load(inputs.resolve_estimate_path(est_path), fmt, est_times, role="est")
    gt = inputs.with_folder_times(gt, est, "--gt-times")
    est = inputs.with_folder_times(est, gt, "--est-times")
    by_index = inputs.pairing_by_index(gt, est)
    ate = evaluate_ate(gt.traj, est.traj, align, max_diff, offset=t_offset, by_index=by_index)
    rpe = evaluate_rpe(gt.traj, est.traj, ate, rpe_delta) if rpe_delta is not None else None
    info = EvalInfo(str(gt.path), str(est.path), len(gt.traj), len(est.traj), max_diff, by_index)
    if plot_path is not None:
        plot_top_view(plot_path, gt.traj, est.traj, ate)
    if results_path is not None:
        save_results(results_path, ate, str(gt.path), str(est.path))
    if as_json:
        out = to_json_dict(info, ate, rpe)
        out["plot"] = plot_path
        out["results"] = results_path
        click.echo(json.dumps(out))
        return
    click.echo(format_text(info, ate, rpe))
    written = [f"plot written to {plot_path}"] if plot_path is not None else []
    if results_path is not None:
        written.append(f"evo results written to {results_path}")
    if written:
        click.echo("\n" + "\n".join(written))
