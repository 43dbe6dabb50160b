"""Scene-consistency masks for the tracker, object propagation and ids, the segmenter interface."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from droidw_cli.config import DynamicsConfig, load_config
from droidw_cli.dynamics.inloop import KeyframeMasks, observed_disparity
from droidw_cli.dynamics.objects import TABLE_COLUMNS, finish
from droidw_cli.dynamics.segmenter import RegionGrower, get_segmenter
from droidw_cli.errors import ConfigError, UserError

H, W = 24, 32
K8 = torch.tensor([30.0, 30.0, (W - 1) / 2, (H - 1) / 2])
BLOCK = (slice(8, 16), slice(12, 20))


def _image(block: tuple[slice, slice] | None) -> np.ndarray:
    """A textured grey wall (working size 8× the grid), optionally a red block."""
    rng = np.random.default_rng(0)
    img = np.repeat(np.repeat(rng.integers(60, 120, (H, W, 1), dtype=np.uint8), 3, axis=2), 8, 0).repeat(8, 1)
    if block is not None:
        img[block[0].start * 8:block[0].stop * 8, block[1].start * 8:block[1].stop * 8] = (220, 30, 30)
    return img


def _poses(n: int, step: float = 0.05) -> torch.Tensor:
    """World-to-camera poses of a camera moving along x (identity rotation)."""
    p = torch.zeros(n, 7)
    p[:, 6] = 1.0
    p[:, 0] = -step * torch.arange(n)
    return p


def test_consistency_finds_the_block_only_where_it_is_nearer_and_ignores_zero_depth():
    masks = KeyframeMasks(DynamicsConfig(mode="consistency"), (H, W), consistency=True)
    for k in range(3):  # the block appears in keyframe 2 only, 1 m in front of a wall at 2 m
        masks.append(_image(BLOCK if k == 2 else None))
    disps = torch.full((3, H, W), 0.5)
    disps[2][BLOCK] = 1.0
    objects = masks.detect(2, _poses(3), disps, K8, [0, 1])
    got = objects.mask
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[BLOCK] = True
    iou = float((got & truth).sum()) / float((got | truth).sum())
    assert iou > 0.8
    # keyframe 0 seen from keyframe 2 shows the wall *behind* the block: farther, so not dynamic
    back = masks.detect(0, _poses(3), disps, K8, [2])
    assert back is None or not bool(back.mask[BLOCK].any())
    # zero (invalid) sensor depth is never flagged
    prior = disps.clone()
    prior[2][BLOCK] = 0.0
    unknown = masks.detect(2, _poses(3), observed_disparity(disps, prior), K8, [0, 1])
    assert unknown is None or not bool(unknown.mask[BLOCK].any())


def test_objects_keep_their_id_and_are_propagated_from_the_previous_centre():
    """The block is masked in keyframes 0, 1 and 3 but missed in 2: propagation from the centre fills it."""
    cfg = DynamicsConfig(mode="consistency")
    masks = KeyframeMasks(cfg, (H, W), consistency=True)
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[BLOCK] = True
    disps = torch.full((4, H, W), 0.5)
    for k in range(4):
        masks.append(_image(BLOCK))
        disps[k][BLOCK] = 1.0
        if k != 2:
            masks.set_current(k, truth)  # the in-loop consistency mask
    poses = _poses(4, step=0.0)  # a still camera and a still block: nothing is inconsistent
    rec = finish(masks, poses, disps, K8, cfg)
    assert rec.masks[2][BLOCK].all()  # propagated
    ids = {int(np.unique(rec.ids[k][truth.numpy()]).item()) for k in range(4)}
    assert len(ids) == 1  # one object, one id
    assert rec.table.shape == (4, len(TABLE_COLUMNS))
    np.testing.assert_allclose(rec.table[:, 6], 1.0, atol=1e-5)  # world centroid depth: the block at 1 m
    assert np.all(np.abs(rec.table[:, 2] - 15.5) <= 1) and np.all(np.abs(rec.table[:, 3] - 11.5) <= 1)


def test_no_propagation_onto_background_that_does_not_look_like_the_object():
    cfg = DynamicsConfig(mode="consistency")
    masks = KeyframeMasks(cfg, (H, W), consistency=True)
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[BLOCK] = True
    disps = torch.full((2, H, W), 0.5)
    disps[0][BLOCK] = 1.0
    masks.append(_image(BLOCK))
    masks.append(_image(None))  # the object left: only the wall at its old centre
    masks.set_current(0, truth)
    rec = finish(masks, _poses(2, step=0.0), disps, K8, cfg)
    assert not rec.masks[1].any()


def test_the_output_mask_leaves_the_in_loop_epipolar_masks_out_only_with_consistency_on():
    """With consistency on, the output is the final consistency mask ∪ the last in-loop one, not the
    dilated epipolar record; without it, the record is all there is."""
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[BLOCK] = True
    halo = torch.zeros(H, W, dtype=torch.bool)
    halo[4:20, 8:24] = True  # an epipolar mask grown around the block
    disps = torch.full((3, H, W), 0.5)
    outputs = {}
    for mode, on in (("both", True), ("epipolar", False)):
        cfg = DynamicsConfig(mode=mode)
        masks = KeyframeMasks(cfg, (H, W), consistency=on)
        for k in range(3):
            masks.append(_image(BLOCK))
            disps[k][BLOCK] = 1.0
            masks.record(k, halo)
        if on:
            masks.set_current(1, truth)
        outputs[mode] = finish(masks, _poses(3, step=0.0), disps, K8, cfg).masks
        assert masks.masks[1].sum() == halo.sum()  # the in-loop record itself is left as it was
    assert (outputs["both"][1] == truth.numpy()).all()
    assert not outputs["both"][0][~truth.numpy()].any()  # no halo anywhere
    assert all((outputs["epipolar"][k] == halo.numpy()).all() for k in range(3))


def test_dynamics_mode_is_validated_and_settable():
    assert load_config("default").dynamics.mode == "epipolar"  # the monocular default (docs/guide.md: dynamic masks)
    assert load_config("rgbd").dynamics.mode == "both"  # the RGB-D default
    cfg = load_config("default", ["dynamics.mode=both"]).dynamics
    assert cfg.epipolar and cfg.consistency
    assert not load_config("default", ["dynamics.mode=none"]).dynamics.epipolar
    with pytest.raises(ConfigError, match="dynamics.mode"):
        load_config("default", ["dynamics.mode=sometimes"])


def test_segmenter_interface():
    seg = get_segmenter("grow")
    assert isinstance(seg, RegionGrower)
    seeds = torch.zeros(H, W, dtype=torch.bool)
    seeds[11:13, 15:17] = True
    image = torch.from_numpy(_image(BLOCK)[4::8, 4::8].astype(np.float32) / 255.0)
    depth = torch.full((H, W), 2.0)
    depth[BLOCK] = 1.0
    grown = seg.segment(seeds, image, depth)
    assert grown.count == 1 and int(grown.areas[0]) == 64  # the whole 8×8 block, nothing else
    with pytest.raises(UserError, match="unknown segmenter"):
        get_segmenter("mobilesam")


def test_detection_gives_the_segmenter_the_grids_focal_lengths():
    """The grower's slant limit needs them (dynamics/refine.py: surface_slant)."""
    masks = KeyframeMasks(DynamicsConfig(mode="both"), (H, W), consistency=True)
    calls = []
    grower = masks.segmenter

    class Spy:
        def segment(self, seeds, image, depth, focal=None):
            calls.append(focal)
            return grower.segment(seeds, image, depth, focal=focal)

    masks.segmenter = Spy()
    disps = torch.full((3, H, W), 0.5)
    for k in range(3):
        masks.append(_image(BLOCK))
        disps[k][BLOCK] = 1.0
    assert masks.detect(2, _poses(3), disps, K8, [0, 1]) is not None
    assert calls == [(30.0, 30.0)]


def test_a_predicted_centre_keeps_the_id_across_a_large_image_motion():
    from droidw_cli.dynamics.tracker import DynamicObjectTracker

    first = np.zeros((H, W), bool)
    first[8:16, 4:10] = True
    second = np.zeros((H, W), bool)
    second[8:16, 18:24] = True  # 14 px to the right: more than 20 % of the width
    plain, told = DynamicObjectTracker(), DynamicObjectTracker()
    a = plain.update(first)[0].id
    assert told.update(first)[0].id == a
    assert plain.update(second)[0].id != a  # lost: a new id
    assert told.update(second, predicted={a: (20.5, 11.5)})[0].id == a


def test_keyframe_colours_are_stored_as_bytes_and_read_as_unit_floats():
    masks = KeyframeMasks(DynamicsConfig(), (6, 8), consistency=False)
    image = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    masks.append(image, 0.0)
    assert masks.images[0].dtype == torch.uint8  # 1 byte a channel: a 10-minute video keeps thousands
    expected = torch.from_numpy(cv2.resize(image, (8, 6), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0)
    assert torch.equal(masks.image(0), expected)
