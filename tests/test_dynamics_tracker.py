"""DynamicObjectTracker: ids by mask overlap, splits and merges, re-identification, the weak-match rules."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.dynamics import DynamicObjectTracker
from droidw_cli.dynamics.association import depth_components, shift_mask

H, W = 60, 100


def _box(x0: int, y0: int, sw: int, sh: int) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[max(0, y0):y0 + sh, max(0, x0):x0 + sw] = True
    return m


def _ids_by_box(objs, boxes: dict[str, np.ndarray]) -> dict[str, int]:
    """The id covering most of each named box."""
    out = {}
    for name, box in boxes.items():
        best = max(objs, key=lambda o: int((o.mask & box).sum()))
        assert (best.mask & box).sum() > 0.5 * box.sum(), name
        out[name] = best.id
    return out


def test_id_is_kept_while_object_moves():
    tr = DynamicObjectTracker()
    ids = []
    for k in range(6):
        objs = tr.update(_box(20 + 4 * k, 20, 12, 12))
        assert len(objs) == 1
        ids.append(objs[0].id)
        assert objs[0].area == 144 and objs[0].mask.sum() == 144
    assert ids == [0] * 6 and tr.ended == []
    assert abs(objs[0].centre[0] - (20 + 20 + 5.5)) <= 0.5  # inscribed-circle centre of the last box


def test_two_objects_keep_their_own_ids():
    tr = DynamicObjectTracker()
    first = tr.update(_box(10, 10, 10, 10) | _box(60, 30, 14, 14))
    side = {o.centre[0] < W / 2: o.id for o in first}
    assert len(side) == 2
    second = tr.update(torch.as_tensor(_box(13, 11, 10, 10) | _box(57, 31, 14, 14)))
    assert len(second) == 2
    for o in second:
        assert o.id == side[o.centre[0] < W / 2]


def test_an_overlapping_object_keeps_its_id_when_it_grows():
    """ADD-SLAM ends a track on a 1.5× area jump; a mask that overlaps the prediction is trusted."""
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(30, 20, 10, 10))
    (b,) = tr.update(_box(31, 18, 14, 18))  # 252 / 100 = 2.5×, but it contains the old box
    assert b.id == a.id and tr.ended == []


def test_a_weak_match_obeys_the_area_and_jump_rules():
    """No overlap: the nearest component is taken only within 1.5× the area and 20 % of the width."""
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(30, 20, 10, 10))
    (b,) = tr.update(_box(42, 20, 11, 11))  # no overlap, 12 px away, 1.2×: the same object
    assert b.id == a.id
    (c,) = tr.update(_box(55, 20, 11, 18))  # no overlap, 1.6× the area: a new object
    assert c.id != a.id
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(10, 20, 10, 10))
    (b,) = tr.update(_box(40, 20, 10, 10))  # 30 px > 20 % of 100, and no overlap: a new object
    assert b.id != a.id


def test_a_blob_missing_for_one_frame_gets_its_id_back():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 20, 12, 12))
    (b,) = tr.update(_box(24, 20, 12, 12))
    assert b.id == a.id
    assert tr.update(np.zeros((H, W), bool)) == []  # missed: dormant, not ended
    assert tr.ended == [] and a.id in tr.dormant
    (c,) = tr.update(_box(32, 20, 12, 12), predicted={a.id: (37.5, 25.5)})
    assert c.id == a.id and a.id in tr.active


def test_a_blob_missing_for_longer_is_lost():
    tr = DynamicObjectTracker(max_missed=2)
    (a,) = tr.update(_box(20, 20, 12, 12))
    for _ in range(2):
        assert tr.update(np.zeros((H, W), bool)) == [] and tr.ended == []
    assert tr.update(np.zeros((H, W), bool)) == []
    assert [(e.id, e.reason) for e in tr.ended] == [(a.id, "lost")]
    (b,) = tr.update(_box(20, 20, 12, 12))
    assert b.id != a.id


def test_a_blob_leaving_and_reentering_gets_a_new_id_but_keeps_it_at_the_border():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 25, 12, 12))
    (b,) = tr.update(_box(6, 25, 12, 12), predicted={a.id: (11.5, 30.5)})
    (c,) = tr.update(_box(-6, 25, 12, 12), predicted={a.id: (-0.5, 30.5)})  # half out, centre x = 2.5 at the border
    assert a.id == b.id == c.id  # still in view: ADD-SLAM would end the track here
    # the prediction leaves the image: the track ends
    assert tr.update(np.zeros((H, W), bool), predicted={a.id: (-20.0, 30.5)}) == []
    assert [(e.id, e.reason) for e in tr.ended] == [(a.id, "left")]
    assert tr.update(_box(0, 25, 4, 12)) == []  # a blob at the border starts no track
    (d,) = tr.update(_box(4, 25, 12, 12))  # back in view: a new id
    assert d.id != a.id


def test_two_blobs_crossing_at_different_depths_keep_their_ids():
    """A near blob passes in front of a far one; they merge into one component while crossing."""
    tr = DynamicObjectTracker()
    ids = None
    for k in range(9):
        xa, xb = 10 + 7 * k, 66 - 7 * k  # a moves right at 1 m, b moves left at 2 m
        near, far = _box(xa, 20, 12, 16), _box(xb, 22, 10, 12)
        depth = np.full((H, W), 4.0)
        depth[far] = 2.0
        depth[near] = 1.0
        mask = near | far
        live = tr.live()
        predicted = {t: (o.centre[0] + (7 if o.depth < 1.5 else -7), o.centre[1]) for t, o in live.items()}
        objs = tr.update(mask, predicted, depth)
        got = _ids_by_box(objs, {"near": near, "far": far & ~near} if (far & ~near).sum() > 20 else {"near": near})
        if ids is None:
            ids = got
        for name, tid in got.items():
            assert tid == ids[name], (k, name)
    assert len(ids) == 2 and ids["near"] != ids["far"]


def test_two_blobs_crossing_at_the_same_depth_keep_their_ids_by_their_predicted_motion():
    tr = DynamicObjectTracker()
    ids = None
    for k in range(9):
        xa, xb = 14 + 7 * k, 70 - 7 * k
        a, b = _box(xa, 20, 12, 16), _box(xb, 21, 12, 16)
        image = np.full((H, W, 3), 0.5)
        image[b] = (0.1, 0.2, 0.9)
        image[a] = (0.9, 0.2, 0.1)  # a in front
        predicted = {t: (o.centre[0] + (7 if o.centre[0] < 40 + 7 * k - 21 else -7), o.centre[1])
                     for t, o in tr.live().items()} if ids else None
        objs = tr.update(a | b, predicted, image=image)
        visible = {"a": a} | ({"b": b & ~a} if (b & ~a).sum() > 40 else {})
        got = _ids_by_box(objs, visible)
        if ids is None:
            ids = got
        for name, tid in got.items():
            assert tid == ids[name], (k, name)
    assert ids["a"] != ids["b"]


def test_where_both_predictions_cover_a_merged_blob_colour_splits_it():
    """Red a (in front) and blue b, both predicted onto the overlap: the colour decides, not the larger overlap."""
    image = np.full((H, W, 3), 0.5)
    a0, b0 = _box(10, 20, 12, 16), _box(60, 18, 12, 20)
    image[a0], image[b0] = (0.9, 0.2, 0.1), (0.1, 0.2, 0.9)
    tr = DynamicObjectTracker()
    first = _ids_by_box(tr.update(a0 | b0, image=image), {"a": a0, "b": b0})
    a1, b1 = _box(32, 20, 12, 16), _box(38, 18, 12, 20)
    image = np.full((H, W, 3), 0.5)
    image[b1] = (0.1, 0.2, 0.9)
    image[a1] = (0.9, 0.2, 0.1)
    predicted = {first["a"]: (37.5, 27.5), first["b"]: (43.5, 27.5)}  # b's larger mask overlaps the blob more
    objs = tr.update(a1 | b1, predicted, image=image)
    assert _ids_by_box(objs, {"a": a1, "b": b1 & ~a1}) == first
    obj_a = next(o for o in objs if o.id == first["a"])
    assert (obj_a.mask & a1).sum() >= 0.8 * a1.sum()


def test_a_mostly_hidden_object_keeps_its_id_and_its_model():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 20, 12, 12))
    (b,) = tr.update(_box(20, 20, 4, 12))  # a third of it left
    assert b.id == a.id and b.occluded and tr.active[a.id].area == 144
    (c,) = tr.update(_box(21, 20, 12, 12))
    assert c.id == a.id and not c.occluded


def test_a_large_jump_is_reidentified_by_colour_only_when_the_colour_matches():
    image = np.full((H, W, 3), 0.5)
    for colour, same in (((0.9, 0.2, 0.1), True), ((0.1, 0.2, 0.9), False)):
        tr = DynamicObjectTracker()
        first, second = _box(10, 20, 12, 14), _box(50, 22, 12, 14)  # 40 px: beyond any centre rule
        im1, im2 = image.copy(), image.copy()
        im1[first] = (0.9, 0.2, 0.1)
        im2[second] = colour
        (a,) = tr.update(first, image=im1)
        (b,) = tr.update(second, image=im2)
        assert (b.id == a.id) == same


def test_depth_components_cut_at_depth_steps():
    mask = _box(10, 10, 20, 10)
    depth = np.full((H, W), 2.0)
    depth[:, 20:] = 3.0  # a step of log 1.5 = 0.41 inside the box
    labels = depth_components(mask, depth, 0.15)
    assert set(np.unique(labels[mask])) == {1, 2}
    assert len(np.unique(labels[mask & (depth == 2.0)])) == 1
    assert len(np.unique(depth_components(mask, None, 0.15)[mask])) == 1
    # a gentle slope is no step
    slope = 2.0 + 0.01 * np.arange(W)[None, :].repeat(H, 0)
    assert len(np.unique(depth_components(mask, slope, 0.15)[mask])) == 1
    objs = DynamicObjectTracker().update(mask, depth=depth)
    assert len(objs) == 2
    # two walkers side by side, 14 % apart in depth (log 0.13): two objects at the default step, one at 0.15
    near = np.where(np.arange(W)[None, :] < 20, 2.0, 2.28).repeat(H, 0)
    assert len(DynamicObjectTracker().update(mask, depth=near)) == 2
    assert len(DynamicObjectTracker(depth_step=0.15).update(mask, depth=near)) == 1


def test_shift_mask_drops_what_leaves_the_image():
    m = _box(0, 0, 4, 4)
    assert shift_mask(m, 2, 1).sum() == 16 and shift_mask(m, 2, 1)[1:5, 2:6].all()
    assert shift_mask(m, -2, 0).sum() == 8
    assert not shift_mask(m, -W, 0).any()


def test_touching_squares_that_swapped_sides_keep_their_ids_by_the_carried_masks():
    """a (left) and b (right) cross and touch, one blob: the masks carried by the flow split it right,
    where the models shifted to their last centres would hand each half to the wrong id."""
    a0, b0 = _box(20, 20, 12, 16), _box(50, 20, 12, 16)
    tr = DynamicObjectTracker(split_colour=0.0)
    first = _ids_by_box(tr.update(a0 | b0), {"a": a0, "b": b0})
    a1, b1 = _box(42, 20, 12, 16), _box(30, 20, 12, 16)  # swapped, touching at x = 42
    carried = {first["a"]: a1, first["b"]: b1}
    assert _ids_by_box(tr.update(a1 | b1, predicted_masks=carried), {"a": a1, "b": b1}) == first
    tr2 = DynamicObjectTracker(split_colour=0.0)
    tr2.update(a0 | b0)
    assert _ids_by_box(tr2.update(a1 | b1), {"a": a1, "b": b1}) != first  # without them the ids swap


def test_a_carried_mask_replaces_the_centre_hypotheses():
    """a is carried by the flow to where the mask misses it; a misleading centre hypothesis on a new
    blob b must not hand b a's id (without the carried mask it does)."""
    a0, b1 = _box(20, 20, 12, 16), _box(60, 20, 12, 16)
    for carried, same in ((True, False), (False, True)):
        tr = DynamicObjectTracker()
        (obj,) = tr.update(a0)
        got = tr.update(b1, predicted={obj.id: (66.0, 28.0)},
                        predicted_masks={obj.id: _box(24, 20, 12, 16)} if carried else None)
        assert (got[0].id == obj.id) == same


def test_a_new_object_needs_min_new_of_the_view():
    """A 90-pixel blob (1.5 % of 60 × 100) starts a track at min_new 0.01, not at 0.02 (dynamics.track_min_new)."""
    blob = _box(40, 20, 9, 10)
    assert [o.area for o in DynamicObjectTracker(min_new=0.01).update(blob)] == [90]
    assert DynamicObjectTracker(min_new=0.02).update(blob) == []


def test_a_partly_matched_object_takes_its_other_piece_instead_of_a_new_id():
    """A track whose prediction found only a sliver (under ``occluded`` of it) takes the nearest piece that
    would otherwise start a new track, under the centre rule's area and jump limits (stopgo RGB-D: a walker
    split by a depth step got a new id for its other half)."""
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 20, 12, 12))
    sliver, piece = _box(20, 20, 3, 12), _box(34, 21, 8, 10)  # 36 px on the prediction, 80 px beside it
    (b,) = tr.update(sliver | piece)
    assert b.id == a.id and b.area == 36 + 80 and tr._next_id == 1
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 20, 12, 12))
    far = _box(60, 21, 8, 10)  # 40 px from the centre, beyond 20 % of the width: a new object
    objs = tr.update(sliver | far)
    assert sorted(o.area for o in objs if o.id == a.id) == [36] and len(objs) == 2


def _ground(boxes: dict[str, tuple[np.ndarray, tuple[float, float, float]]]) -> np.ndarray:
    """(H, W, 2) places on the floor: each box's pixels stand at its (x, y), spread ±0.1 m across the box; NaN
    elsewhere."""
    out = np.full((H, W, 2), np.nan)
    for box, pos in boxes.values():
        ys, xs = np.nonzero(box)
        out[ys, xs] = np.asarray(pos) + np.stack([0.2 * (xs - xs.mean()) / max(np.ptp(xs), 1), np.zeros(len(xs))], 1)
    return out


def test_the_ground_cue_splits_a_merged_blob_by_where_each_walker_stands():
    """Two boxes at the same depth that touch in the image, with swapped image predictions: the image cues
    swap their ids; their predicted places on the floor keep them."""
    a0, b0 = _box(10, 20, 12, 16), _box(60, 20, 12, 16)
    ga, gb = (0.0, 2.0), (1.0, 2.0)
    a1, b1 = _box(30, 20, 12, 16), _box(42, 20, 12, 16)  # touching: one component
    ga1, gb1 = (0.2, 2.0), (0.8, 2.0)
    depth = np.full((H, W), 2.0)
    for cue in (True, False):
        tr = DynamicObjectTracker()
        first = _ids_by_box(tr.update(a0 | b0, depth=depth, ground=_ground({"a": (a0, ga), "b": (b0, gb)}) if cue
                                      else None), {"a": a0, "b": b0})
        swapped = {first["a"]: (47.5, 27.5), first["b"]: (35.5, 27.5)}  # each image prediction on the other box
        ground = _ground({"a": (a1, ga1), "b": (b1, gb1)}) if cue else None
        objs = tr.update(a1 | b1, swapped, depth, ground=ground,
                         predicted_ground={first["a"]: np.array(ga1), first["b"]: np.array(gb1)} if cue else None)
        got = _ids_by_box(objs, {"a": a1, "b": b1})
        if cue:
            assert got == first
            obj_a = next(o for o in objs if o.id == first["a"])
            assert (obj_a.mask & a1).sum() == a1.sum() and not (obj_a.mask & b1).any()
        else:
            assert got == {"a": first["b"], "b": first["a"]}


def test_the_ground_cue_claims_a_component_that_the_image_prediction_misses():
    """A box 40 px from its predicted image place (beyond ADD-SLAM's 20 % jump) where it was predicted to stand
    on the floor keeps its id; without the cue it gets a new one."""
    depth = np.full((H, W), 2.0)
    a0, a1 = _box(10, 20, 12, 16), _box(50, 20, 12, 16)
    for cue in (True, False):
        tr = DynamicObjectTracker()
        (o0,) = tr.update(a0, depth=depth, ground=_ground({"a": (a0, (0.0, 2.0))}) if cue else None)
        (o1,) = tr.update(a1, {o0.id: o0.centre}, depth, ground=_ground({"a": (a1, (0.6, 2.0))}) if cue else None,
                          predicted_ground={o0.id: np.array([0.55, 2.0])} if cue else None)
        assert (o1.id == o0.id) == cue


def test_tracks_predicted_in_one_place_on_the_floor_are_split_by_the_image():
    """Two claimers predicted at the same place on the floor (walkers passing through each other): the floor
    cannot part them (equal costs give one track the whole blob), so the image predictions split it."""
    a0, b0 = _box(10, 20, 12, 16), _box(60, 20, 12, 16)
    a1, b1 = _box(30, 20, 12, 16), _box(42, 20, 12, 16)
    depth = np.full((H, W), 2.0)
    for apart, split in ((0.15, True), (0.0, False)):
        tr = DynamicObjectTracker(ground_apart=apart)
        ground = _ground({"a": (a0, (0.0, 2.0)), "b": (b0, (1.0, 2.0))})
        first = _ids_by_box(tr.update(a0 | b0, depth=depth, ground=ground), {"a": a0, "b": b0})
        here = {first["a"]: (35.5, 27.5), first["b"]: (47.5, 27.5)}
        same = {first["a"]: np.array([0.5, 2.0]), first["b"]: np.array([0.5, 2.0])}
        objs = tr.update(a1 | b1, here, depth, ground=_ground({"a": (a1, (0.45, 2.0)), "b": (b1, (0.55, 2.0))}),
                         predicted_ground=same)
        assert (len(objs) == 2 and _ids_by_box(objs, {"a": a1, "b": b1}) == first) == split
