"""Round trips and parsing rules of droidw_cli.io.trajectory (TUM, KITTI, EuRoC)."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.errors import InputError
from droidw_cli.io.trajectory import (
    Trajectory,
    detect_format,
    matrix_to_quat_xyzw,
    pose_from_tq,
    quat_xyzw_to_matrix,
    read_kitti,
    read_trajectory,
    tq_from_pose,
    write_trajectory,
)

RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
H = float(np.sqrt(0.5))


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return quat_xyzw_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))


def random_trajectory(rng: np.random.Generator, n: int = 25, t0: float = 1305031102.0) -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = random_rotations(rng, n)
    poses[:, :3, 3] = rng.normal(scale=3.0, size=(n, 3))
    # microsecond timestamps: exactly what TUM's 6 decimals can hold
    stamps = t0 + np.round(np.cumsum(rng.uniform(0.02, 0.05, size=n)), 6)
    return Trajectory(stamps, poses)


@pytest.mark.parametrize("fmt,name", [("tum", "t.txt"), ("kitti", "k.txt"), ("euroc", "e.csv")])
def test_round_trip_every_format(tmp_path, fmt, name):
    rng = np.random.default_rng(7)
    traj = random_trajectory(rng)
    path = tmp_path / name
    write_trajectory(path, traj, fmt)
    assert detect_format(path) == fmt
    back = read_trajectory(path)  # auto-detected
    assert len(back) == len(traj)
    np.testing.assert_allclose(back.poses[:, :3, 3], traj.poses[:, :3, 3], atol=1e-8)
    np.testing.assert_allclose(back.poses[:, :3, :3], traj.poses[:, :3, :3], atol=1e-8)
    np.testing.assert_allclose(back.poses[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (len(traj), 1)))
    if fmt == "kitti":
        np.testing.assert_array_equal(back.timestamps, np.arange(len(traj), dtype=float))
    else:
        # EuRoC stores integer nanoseconds; float64 seconds near 1.3e9 resolve ~0.24 µs
        np.testing.assert_allclose(back.timestamps, traj.timestamps, rtol=0, atol=1e-6)
    # a second round trip is stable
    write_trajectory(tmp_path / ("again_" + name), back, fmt)
    again = read_trajectory(tmp_path / ("again_" + name), fmt)
    np.testing.assert_allclose(again.poses, back.poses, atol=1e-9)


def test_kitti_times_file(tmp_path):
    rng = np.random.default_rng(3)
    traj = random_trajectory(rng, n=6)
    write_trajectory(tmp_path / "k.txt", traj, "kitti")
    (tmp_path / "times.txt").write_text("\n".join(f"{t:.6f}" for t in traj.timestamps) + "\n")
    back = read_kitti(tmp_path / "k.txt", tmp_path / "times.txt")
    np.testing.assert_allclose(back.timestamps, traj.timestamps, atol=1e-6)
    (tmp_path / "short.txt").write_text("0.0\n0.1\n")
    with pytest.raises(InputError, match="2 timestamps for 6 poses"):
        read_kitti(tmp_path / "k.txt", tmp_path / "short.txt")


def test_quaternion_order_tum_xyzw_and_euroc_wxyz_agree(tmp_path):
    # 90 degrees about z: (qx, qy, qz, qw) = (0, 0, sqrt(1/2), sqrt(1/2))
    (tmp_path / "z.txt").write_text(f"# t tx ty tz qx qy qz qw\n1.0 1 2 3 0 0 {H} {H}\n")
    (tmp_path / "z.csv").write_text(f"#timestamp,px,py,pz,qw,qx,qy,qz\n1000000000,1,2,3,{H},0,0,{H}\n")
    tum = read_trajectory(tmp_path / "z.txt")
    euroc = read_trajectory(tmp_path / "z.csv")
    np.testing.assert_allclose(tum.poses[0, :3, :3], RZ90, atol=1e-12)
    np.testing.assert_allclose(euroc.poses[0, :3, :3], RZ90, atol=1e-12)
    np.testing.assert_allclose(tum.poses, euroc.poses, atol=1e-12)
    assert tum.timestamps[0] == pytest.approx(euroc.timestamps[0])


def test_quaternion_order_swapped_gives_a_different_rotation(tmp_path):
    # the same numbers in the other order: qx = 1/sqrt2, qw = 1/sqrt2 is 90 degrees about x
    (tmp_path / "wrong.txt").write_text(f"1.0 0 0 0 {H} 0 0 {H}\n")
    (tmp_path / "wrong.csv").write_text(f"1000000000,0,0,0,0,0,{H},{H}\n")
    rx90 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    tum = read_trajectory(tmp_path / "wrong.txt").poses[0, :3, :3]
    euroc = read_trajectory(tmp_path / "wrong.csv").poses[0, :3, :3]
    np.testing.assert_allclose(tum, rx90, atol=1e-12)
    assert np.abs(tum - RZ90).max() > 0.5
    assert np.abs(euroc - RZ90).max() > 0.5  # EuRoC reads (0, 0, h, h) as w=0, x=0, y=h, z=h


def test_written_quaternion_columns(tmp_path):
    traj = Trajectory(np.array([2.5]), pose_from_tq(np.array([[1.0, 2.0, 3.0]]), np.array([[0.0, 0.0, H, H]])))
    write_trajectory(tmp_path / "a.txt", traj, "tum")
    write_trajectory(tmp_path / "a.csv", traj, "euroc")
    tum_vals = [float(v) for v in (tmp_path / "a.txt").read_text().splitlines()[1].split()]
    euroc_vals = [float(v) for v in (tmp_path / "a.csv").read_text().splitlines()[1].split(",")]
    np.testing.assert_allclose(tum_vals[4:], [0.0, 0.0, H, H], atol=1e-9)  # x y z w
    np.testing.assert_allclose(euroc_vals[4:], [H, 0.0, 0.0, H], atol=1e-9)  # w x y z
    assert euroc_vals[0] == 2500000000


def test_quaternion_matrix_round_trip_all_branches():
    rng = np.random.default_rng(11)
    rots = random_rotations(rng, 200)
    # add rotations by ~180 degrees about each axis (negative-trace branches of Shepperd's method)
    flips = np.array([np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])])
    rots = np.concatenate([rots, flips])
    q = matrix_to_quat_xyzw(rots)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(quat_xyzw_to_matrix(q), rots, atol=1e-12)
    t, q2 = tq_from_pose(pose_from_tq(np.zeros((len(rots), 3)), q))
    np.testing.assert_allclose(q2, q, atol=1e-12)


def test_non_unit_quaternion_is_normalised(tmp_path):
    (tmp_path / "n.txt").write_text("0.0 0 0 0 0 0 2 2\n")
    r = read_trajectory(tmp_path / "n.txt").poses[0, :3, :3]
    np.testing.assert_allclose(r, RZ90, atol=1e-12)


@pytest.mark.parametrize(
    "name,text,lineno,fragment",
    [
        ("bad.txt", "# header\n0.0 0 0 0 0 0 0 1\n0.1 0 0 zero 0 0 0 1\n", 3, "not a number"),
        ("cols.txt", "0.0 0 0 0 0 0 0 1\n\n0.1 0 0 0 0 0 1\n", 3, "expected 8"),
        ("nan.txt", "0.0 0 0 0 0 0 0 1\n0.1 nan 0 0 0 0 0 1\n", 2, "NaN"),
        ("zq.txt", "0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 0\n", 2, "zero quaternion"),
        ("bad.csv", "#timestamp,x\n1,0,0,0,1,0,0,0\n2,0,0,0,1,0,oops,0\n", 3, "not a number"),
        ("short.csv", "1,0,0,0,1,0,0,0\n2,0,0,0,1\n", 2, "at least 8"),
    ],
)
def test_malformed_line_reports_file_and_line(tmp_path, name, text, lineno, fragment):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_trajectory(path)
    msg = str(info.value)
    assert f"{path}:{lineno}" in msg
    assert fragment in msg
    assert "\n" not in msg


def test_kitti_malformed_line(tmp_path):
    path = tmp_path / "k.txt"
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(InputError, match=f"{path}:2"):
        read_trajectory(path, "kitti")


def test_missing_empty_and_unknown(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_trajectory(tmp_path / "none.txt")
    (tmp_path / "empty.txt").write_text("# only a comment\n")
    with pytest.raises(InputError, match="no poses"):
        read_trajectory(tmp_path / "empty.txt", "tum")
    (tmp_path / "odd.txt").write_text("1 2 3\n")
    with pytest.raises(InputError, match="--format"):
        read_trajectory(tmp_path / "odd.txt")
    (tmp_path / "ok.txt").write_text("0 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError, match="unknown trajectory format"):
        read_trajectory(tmp_path / "ok.txt", "ply")


def test_write_is_atomic_and_leaves_no_temporaries(tmp_path):
    traj = random_trajectory(np.random.default_rng(5), n=4)
    out = tmp_path / "sub" / "traj.txt"
    write_trajectory(out, traj, "tum")
    write_trajectory(out, traj, "tum")  # overwrite in place
    assert [p.name for p in out.parent.iterdir()] == ["traj.txt"]
    assert len(read_trajectory(out)) == 4
