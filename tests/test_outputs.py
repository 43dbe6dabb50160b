"""Output paths are checked before the work (one line, exit 2), and an OSError never prints a traceback."""

from __future__ import annotations

import errno

import numpy as np
import pytest

from cli_run import run
from droidw_cli.io.outputs import OutputError, check_output_file, check_output_folder, describe_os_error


def test_checks_name_the_user_path(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(OutputError, match="exists and is not a folder"):
        check_output_folder(afile)
    with pytest.raises(OutputError, match="is not a folder"):
        check_output_folder(afile / "sub" / "run")
    with pytest.raises(OutputError, match="is not a folder"):
        check_output_file(afile / "x.png")
    with pytest.raises(OutputError, match="is a folder"):
        check_output_file(tmp_path)
    assert check_output_folder(tmp_path / "new" / "run") == (tmp_path / "new" / "run").absolute()
    assert not (tmp_path / "new").exists()  # only looked
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # the probe left nothing


def test_os_error_names_the_folder_not_a_temporary_file():
    exc = FileNotFoundError(errno.ENOENT, "No such file or directory", "/data/out/.x.png.1234.tmp")
    assert describe_os_error(exc) == "cannot write into /data/out: No such file or directory"
    exc = PermissionError(errno.EACCES, "Permission denied", "/data/traj.txt")
    assert describe_os_error(exc) == "/data/traj.txt: Permission denied"


def _tum(path, n=10):
    rows = [f"{i:.1f} {0.1 * i} 0 0 0 0 0 1" for i in range(n)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_track_refuses_a_file_as_output_folder_before_tracking(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("x")
    code, out, err = run(["track", str(tmp_path / "missing-input"), "--out", str(afile), "--quiet"], capsys)
    assert code == 2 and "Traceback" not in err
    # the output check comes first: it names the output even though the input is missing too
    assert "afile exists and is not a folder" in err, err
    assert afile.read_text() == "x"


def test_eval_refuses_a_plot_under_a_file(tmp_path, capsys):
    gt = _tum(tmp_path / "gt.txt")
    afile = tmp_path / "afile"
    afile.write_text("x")
    code, out, err = run(["eval", "--gt", str(gt), "--est", str(gt), "--plot", str(afile / "top.png")], capsys)
    assert code == 2 and "is not a folder" in err, err
    assert np.loadtxt(gt).shape == (10, 8)
