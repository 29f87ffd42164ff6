"""Triangulating a handle from per-view sightings: exact on clean views, robust to wrong ones; and
several handles (furniture) from several sightings per view."""

from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame
from nfr_drake.perception.handle_triangulation import (
    FURNITURE_LOOSE,
    HandleMap,
    HandleSighting,
    TriangulatedHandle,
    bar_sightings,
    in_front,
    in_most_images,
    inside_masks,
    locate_handles,
    sighting,
    sightings,
    triangulate_bars,
    triangulate_handle,
    triangulate_handles,
)

P_TRUE = np.array([0.25, -0.2, 0.5])


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """X_OC with OpenCV axes (z forward, y down) looking from eye at target."""
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    X = np.eye(4)
    X[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    X[:3, 3] = eye
    return X


def _frames(n: int, size: int, distortion=None, distance: float = 1.6) -> list[CaptureFrame]:
    cam = PinholeCamera.from_fov(size, size, np.radians(50.0))
    if distortion is not None:
        cam = PinholeCamera(cam.fx, cam.fy, cam.cx, cam.cy, size, size, distortion)
    frames = []
    for az in np.linspace(-50, 50, n):
        a = np.radians(az)
        eye = np.array([distance * np.cos(a), distance * np.sin(a), 1.0])
        frames.append(CaptureFrame(Path(f"{az}.png"), _look_at(eye, np.array([0.0, 0, 0.5])), cam))
    return frames


def _project(frame: CaptureFrame, p: np.ndarray) -> np.ndarray:
    X_CO = np.linalg.inv(frame.X_OC)
    p_C = X_CO[:3, :3] @ p + X_CO[:3, 3]
    cam = frame.camera
    x, y = p_C[:2] / p_C[2]
    if cam.distortion:
        k1, k2, p1, p2 = cam.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
    return np.array([cam.fx * x + cam.cx, cam.fy * y + cam.cy])


def _blob(size: int, uv: np.ndarray) -> HandleMap:
    """A 3 x 3 px probability blob centred on pixel uv (sub-pixel weights), without offsets."""
    prob = np.zeros((size, size), np.float32)
    c, r = uv - 0.5
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            rr, cc = int(round(r)) + dr, int(round(c)) + dc
            prob[rr, cc] = max(0.0, 1.0 - 0.4 * np.hypot(rr - r, cc - c))
    return HandleMap.centroid_only(prob)


@pytest.mark.parametrize("distortion", [None, (-0.1, 0.02, 0.001, -0.001)])
def test_exact_views_give_the_point(distortion):
    frames = _frames(8, 128, distortion)
    found = [sighting(_blob(128, _project(f, P_TRUE)), i) for i, f in enumerate(frames)]
    assert all(s is not None for s in found)
    result = triangulate_handle(frames, found)
    assert result is not None and len(result.views) == 8
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005  # a blob's centroid is within ~0.2 px
    assert result.rms_px < 0.5


def test_wrong_sightings_are_left_out():
    frames = _frames(10, 128)
    found = [sighting(_blob(128, _project(f, P_TRUE)), i) for i, f in enumerate(frames)]
    decoy = P_TRUE + [0.0, 0.4, 0.0]  # three views "see" the handle 40 cm to the side
    for i in (1, 4, 7):
        found[i] = sighting(_blob(128, _project(frames[i], decoy)), i)
    result = triangulate_handle(frames, found)
    assert result is not None
    assert set(result.views) == set(range(10)) - {1, 4, 7}
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005


def test_too_few_agreeing_views_give_none():
    frames = _frames(4, 64)
    offsets = np.array([[0, 0, 0], [0, 0, 0.15], [0, -0.2, -0.1], [0.1, 0.2, 0.2]])
    found = [sighting(_blob(64, _project(f, P_TRUE + o)), i)
             for i, (f, o) in enumerate(zip(frames, offsets, strict=True))]  # each sees another
    assert triangulate_handle(frames, found) is None
    assert triangulate_handle(frames, found[:2]) is None


def test_sighting_takes_the_strongest_blob():
    prob = np.zeros((32, 32), np.float32)
    prob[5, 5] = 0.6  # a weak speck
    prob[20:23, 10:12] = 0.9  # the handle
    s = sighting(HandleMap.centroid_only(prob), 3)
    assert s is not None and s.frame == 3
    np.testing.assert_allclose(s.uv, [11.0, 21.5])
    assert sighting(HandleMap.centroid_only(np.full((8, 8), 0.4, np.float32)), 0) is None


def test_a_blob_on_the_masks_edge_is_left_out_inside_the_mask():
    """A room photo painted off the object's mask: a strong blob along the mask's bottom edge (the
    cut) outweighs the weaker handle blob in the middle, until the map is kept inside the mask."""
    mask = np.zeros((128, 128), np.float32)
    mask[20:80, 24:104] = 1.0
    prob = np.zeros((128, 128), np.float32)
    prob[77:82, 28:100] = 0.95  # along the bottom edge, 3 px in and 2 px out
    prob[48:50, 52:76] = 0.8  # the handle
    handle_map = HandleMap.centroid_only(prob)
    assert sighting(handle_map, 0).uv[1] > 77
    kept = inside_masks([handle_map], [mask])[0]
    np.testing.assert_allclose(sighting(kept, 0).uv, [64.0, 49.0])
    # the margin scales with the image: 2 px in is on the edge at 128 px, inside at 64 px
    edge = np.zeros((128, 128), np.float32)
    edge[78, 40:80] = 0.9
    assert sighting(HandleMap.centroid_only(edge).inside(mask), 0) is None
    small = HandleMap.centroid_only(edge[::2, ::2]).inside(mask[::2, ::2])
    assert sighting(small, 0) is None
    edge_small = np.zeros((64, 64), np.float32)
    edge_small[38, 20:40] = 0.9
    assert sighting(HandleMap.centroid_only(edge_small).inside(mask[::2, ::2]), 0) is not None


def test_sighting_is_where_the_blob_votes():
    """Offsets that all point at one spot put the sighting there, wherever the blob's centroid."""
    prob = np.zeros((32, 32), np.float32)
    prob[20:23, 10:14] = [0.6, 0.9, 0.9, 0.7]
    rows, cols = np.mgrid[0:32, 0:32]
    target = np.array([15.3, 18.8])
    offset = np.stack([target[0] - (cols + 0.5), target[1] - (rows + 0.5)], -1).astype(np.float32)
    s = sighting(HandleMap(prob, offset), 0)
    np.testing.assert_allclose(s.uv, target, atol=1e-5)
    assert abs(s.mass - prob.sum()) < 1e-5


def test_strong_sightings_outweigh_more_numerous_weak_ones():
    """Four faint partial blobs agree on a point 8 cm off; three full ones on the handle."""
    frames = _frames(7, 128)
    decoy = P_TRUE + [0.0, 0.0, -0.08]
    found = []
    for i, f in enumerate(frames):
        strong = i in (1, 3, 5)
        blob = _blob(128, _project(f, P_TRUE if strong else decoy))
        prob = blob.probability * (1.0 if strong else 0.3)
        found.append(sighting(HandleMap.centroid_only(prob), i, threshold=0.1))
    result = triangulate_handle(frames, found)
    assert result is not None and set(result.views) == {1, 3, 5}
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005


def _votes_map(size: int, handles_uv: list[np.ndarray], spread: int = 2) -> HandleMap:
    """A bar of pixels beside each handle projection (none centred on it) whose offsets point at
    that handle: what the detector gives for several handles."""
    prob = np.zeros((size, size), np.float32)
    offset = np.zeros((size, size, 2), np.float32)
    for uv in handles_uv:
        c, r = int(uv[0]), int(uv[1]) + 1
        for dc in range(-spread, spread + 1):
            if 0 <= r < size and 0 <= c + dc < size:
                prob[r, c + dc] = 0.9
                offset[r, c + dc] = uv - [c + dc + 0.5, r + 0.5]
    return HandleMap(prob, offset)


def test_sightings_give_one_per_handle_where_the_votes_point():
    """Two handles 6 px apart, their pixels in one connected blob: two sightings, each where its
    pixels vote; a faint speck is no sighting."""
    a, b = np.array([10.3, 12.2]), np.array([16.4, 12.6])
    m = _votes_map(32, [a, b])
    m.probability[25, 25] = 0.6  # a speck of mass 0.6 that votes for itself, kept, then dropped
    found = sightings(m, 4)
    assert sorted(tuple(np.round(s.uv, 3)) for s in found[:2]) == [tuple(np.round(a, 3)),
                                                                   tuple(np.round(b, 3))]
    assert all(s.frame == 4 for s in found) and found[0].mass >= found[-1].mass
    assert len(sightings(m, 4, min_mass=1.0)) == 2
    assert sightings(HandleMap.centroid_only(np.zeros((8, 8), np.float32)), 0) == []


def test_several_handles_are_triangulated_each_once():
    """Four handles of a piece seen in 8 views (one view misses one handle, one view has a wrong
    extra sighting): four points, each within 5 mm, two of them 10 cm apart (a pair of doors)."""
    frames = _frames(8, 128)
    handles = P_TRUE + np.array([[0, 0, 0], [0, 0.3, 0], [0, 0, -0.25], [0, 0.1, 0.0]])
    found = []
    for i, f in enumerate(frames):
        seen = [_project(f, p) for k, p in enumerate(handles) if not (i == 2 and k == 1)]
        if i == 5:
            seen.append(_project(f, P_TRUE + [0.3, -0.3, 0.3]))
        found += sightings(_votes_map(128, seen), i)
    points = triangulate_handles(frames, found)
    assert len(points) == 4
    for p in handles:
        assert min(np.linalg.norm(h.p_O - p) for h in points) < 0.005
    assert all(len(h.views) >= 7 for h in points)
    assert triangulate_handles(frames, found[:2]) == []


def test_a_point_seen_in_few_of_the_views_it_is_in_is_dropped_with_min_share():
    """A 'handle' sighted in 3 of the 10 views it projects into is a point with min_share 0 and
    none with min_share 0.5; the real handle, sighted in all 10, stays."""
    frames = _frames(10, 128)
    decoy = P_TRUE + [0.0, 0.2, 0.1]
    found = []
    for i, f in enumerate(frames):
        seen = [_project(f, P_TRUE)] + ([_project(f, decoy)] if i in (0, 4, 8) else [])
        found += sightings(_votes_map(128, seen), i)
    assert len(triangulate_handles(frames, found)) == 2
    (kept,) = triangulate_handles(frames, found, min_share=0.5)
    assert np.linalg.norm(kept.p_O - P_TRUE) < 0.005


@pytest.mark.parametrize("step, points", [((0.0, 0.06, 0.0), 2), ((0.0, 0.0, 0.05), 1)])
def test_close_handles_side_by_side_stay_two(step, points):
    """Two sighted points 3-6 px apart in every view: side by side (a pair of doors' handles, 6 cm
    apart in y) they are two handles; one above the other (a bar the detector split in two) one.
    Without the side-by-side exception the pair is one handle too."""
    frames = _frames(8, 128)
    pair = [P_TRUE, P_TRUE + np.array(step)]
    assert all(2.5 < np.linalg.norm(_project(f, pair[0]) - _project(f, pair[1])) < 6.0 for f in frames)
    found = [s for i, f in enumerate(frames)
             for s in sightings(_votes_map(128, [_project(f, p) for p in pair], spread=1), i)]
    assert len(triangulate_handles(frames, found)) == points
    assert len(triangulate_handles(frames, found, side_by_side_m=np.inf)) == 1


def test_a_point_few_views_agree_with_loosely_is_dropped_by_the_loose_rule():
    """Sighted in 5 of the 10 views it projects into: 2 px off in alternate directions (edges that
    line up by chance) it is a point without the loose rule and none with it
    (`FURNITURE_LOOSE`); sighted as closely as the true handle it stays either way."""
    frames = _frames(10, 128)
    decoy = P_TRUE + [0.0, 0.25, 0.1]
    share, rms_px = FURNITURE_LOOSE

    def found(jitter_px: float) -> list:
        out = []
        for i, f in enumerate(frames):
            seen = [_project(f, P_TRUE)]
            if i % 2 == 0:
                seen.append(_project(f, decoy) + [0.0, jitter_px * (-1) ** (i // 2)])
            out += sightings(_votes_map(128, seen), i)
        return out

    loose = found(2.0)
    assert len(triangulate_handles(frames, loose, min_share=0.5)) == 2
    (kept,) = triangulate_handles(frames, loose, min_share=0.5, loose_share=share, loose_rms_px=rms_px)
    assert np.linalg.norm(kept.p_O - P_TRUE) < 0.005
    assert len(triangulate_handles(frames, found(0.0), min_share=0.5, loose_share=share,
                                   loose_rms_px=rms_px)) == 2


def test_a_point_between_two_close_handles_does_not_outscore_them():
    """Two handles 8 cm apart, each sighted in every view, one heavy (mass 8) in the left views
    and light (3) in the right ones, the other the reverse: a point between them at another
    depth agrees loosely with the heavy sighting of every view and outweighs either handle by
    mass alone; weighed by closeness (MSAC) each handle is found, within 3 mm."""
    frames = _frames(10, 128)
    pair = [P_TRUE, P_TRUE + np.array([0.0, 0.08, 0.0])]
    found = []
    for i, f in enumerate(frames):
        masses = (8.0, 3.0) if i < 5 else (3.0, 8.0)
        found += [HandleSighting(i, _project(f, p), m) for p, m in zip(pair, masses, strict=True)]
    points = triangulate_handles(frames, found)
    assert len(points) == 2
    for p in pair:
        assert min(np.linalg.norm(h.p_O - p) for h in points) < 0.003


def test_views_where_an_earlier_handle_merges_with_a_point_leave_its_share():
    """Two handles 5 cm side by side (a pair of doors' knobs): where they project within 4 px the
    detector gives one sighting, the first handle's, and the second is sighted in 4 of the 10
    views. With min_share 0.5 it is lost; with merged_px 4 those views leave its share and it is
    found within 5 mm. A point sighted in 3 views away from any handle stays dropped."""
    frames = _frames(10, 128)
    first, second = P_TRUE, P_TRUE + np.array([0.0, 0.05, 0.0])
    decoy = P_TRUE + np.array([0.0, -0.25, 0.1])
    gaps = [np.linalg.norm(_project(f, first) - _project(f, second)) for f in frames]
    merged = [i for i, g in enumerate(gaps) if g < 4.0]
    assert len(merged) >= 4
    seen_apart = [i for i, g in enumerate(gaps) if g >= 4.0][:4]
    found = []
    for i, f in enumerate(frames):
        found.append(HandleSighting(i, _project(f, first), 5.0))
        if i in seen_apart:
            found.append(HandleSighting(i, _project(f, second), 5.0))
        if i in (0, 4, 8):
            found.append(HandleSighting(i, _project(f, decoy), 5.0))
    assert len(triangulate_handles(frames, found, min_share=0.5)) == 1
    points = triangulate_handles(frames, found, min_share=0.5, merged_px=4.0)
    assert len(points) == 2
    assert min(np.linalg.norm(h.p_O - second) for h in points) < 0.005
    assert max(len(h.views) for h in points) == 10


def test_a_point_behind_every_other_one_is_no_handle():
    """A point 8 cm behind three handles on the fronts' plane is left out; one 2 cm behind stays,
    and so do handles in front (open fronts); with fewer than two others nothing is left out."""
    def handle(x):
        return TriangulatedHandle(np.array([x, 0.0, 0.5]), (0, 1, 2), 0.5, 10)

    shut = [handle(0.30), handle(0.31), handle(0.60)]  # the last one on an open front
    kept = in_front(shut + [handle(0.22), handle(0.28)], behind_m=0.05)
    assert [h.p_O[0] for h in kept] == [0.30, 0.31, 0.60, 0.28]
    assert len(in_front([handle(0.30), handle(0.10)], behind_m=0.05)) == 2
    assert in_front([], behind_m=0.05) == []


def _bar_map(size: int, frame: CaptureFrame, ends: list[tuple[np.ndarray, np.ndarray]],
             shift_px: float) -> HandleMap:
    """Each bar's pixels between the projections of its ends (3D points in O), 1 px wide, their
    votes at `shift_px` along the bar from its middle: the detector on a long bar, its votes off
    by another distance in each view."""
    prob = np.zeros((size, size), np.float32)
    offset = np.zeros((size, size, 2), np.float32)
    for a, b in ends:
        uv_a, uv_b = _project(frame, a), _project(frame, b)
        axis = (uv_b - uv_a) / np.linalg.norm(uv_b - uv_a)
        for t in np.linspace(0.0, 1.0, 4 * int(np.linalg.norm(uv_b - uv_a)) + 1):
            c, r = (uv_a + t * (uv_b - uv_a)).astype(int)
            prob[r, c] = 0.9
            wrong = (uv_a + uv_b) / 2 + shift_px * axis
            offset[r, c] = wrong - [c + 0.5, r + 0.5]
    return HandleMap(prob, offset)


def test_an_upright_bar_whose_votes_disagree_is_found_from_its_pixels():
    """A door's 40 cm upright bar detected in every view, its votes scattered along it: no point
    from the votes, and one bar from the pixels (`bar_sightings`, `triangulate_bars`), its middle
    within 1 cm; segments a point already explains give no second handle; a horizontal bar (a
    drawer's pull, whose votes the points find) seen the same way is no bar."""
    frames = _frames(10, 128)
    shifts = np.random.default_rng(0).permutation(np.linspace(-12.0, 12.0, 10))  # 2.7 px apart
    upright = (P_TRUE - [0, 0, 0.2], P_TRUE + [0, 0, 0.2])
    maps = [_bar_map(128, f, [upright], d) for f, d in zip(frames, shifts, strict=True)]
    assert triangulate_handles(frames, [s for i, m in enumerate(maps) for s in sightings(m, i)],
                               min_share=0.5) == []
    segments = [b for i, m in enumerate(maps) for b in bar_sightings(m, i)]
    assert len(segments) == 10 and all(abs(b.axis[1]) > 0.95 for b in segments)
    (bar,) = triangulate_bars(frames, segments, [], min_share=0.5)
    assert np.linalg.norm(bar.p_O - P_TRUE) < 0.01 and len(bar.views) == 10
    (located,) = locate_handles(maps, frames)
    assert np.linalg.norm(located.p_O - P_TRUE) < 0.01
    assert locate_handles(maps, frames, bars=False) == []
    assert triangulate_bars(frames, segments, [bar], min_share=0.5) == []
    level = (P_TRUE - [0, 0.2, 0], P_TRUE + [0, 0.2, 0])
    flat = [b for i, f in enumerate(frames) for b in bar_sightings(_bar_map(128, f, [level], 0.0), i)]
    assert len(flat) == 10 and triangulate_bars(frames, flat, [], min_share=0.5) == []


def test_a_bar_seen_in_too_few_views_is_dropped_with_min_share():
    """An upright bar's pixels in 3 of the 10 views it projects into: a bar with min_share 0,
    none with 0.5."""
    frames = _frames(10, 128)
    upright = (P_TRUE - [0, 0, 0.2], P_TRUE + [0, 0, 0.2])
    segments = [b for i, f in enumerate(frames) if i in (1, 4, 8)
                for b in bar_sightings(_bar_map(128, f, [upright], 0.0), i)]
    assert len(triangulate_bars(frames, segments, [], min_share=0.0)) == 1
    assert triangulate_bars(frames, segments, [], min_share=0.5) == []


def test_point_sightings_on_a_bar_count_as_its_views():
    """An upright bar seen whole (a segment) in 3 of the 10 views and, in the other 7, only as a
    point sighting somewhere along it (its votes off its middle by up to 15 cm): with min_share
    0.5 no bar from the segments alone, and one within 1.5 cm of the bar's middle (three
    segments' pixel ends place it), agreeing with all 10 views, with the points. Points beside
    the bar (8 cm to its side) or past its ends add no view, a point a handle already explains
    is not the bar's, and two segments with points in every other view make no bar (the points
    count toward the share only)."""
    frames = _frames(10, 128)
    upright = (P_TRUE - [0, 0, 0.2], P_TRUE + [0, 0, 0.2])
    whole = (1, 4, 8)
    segments = [b for i, f in enumerate(frames) if i in whole
                for b in bar_sightings(_bar_map(128, f, [upright], 0.0), i)]
    along = np.linspace(-0.15, 0.15, 7)
    others = [i for i in range(10) if i not in whole]
    on_bar = [HandleSighting(i, _project(frames[i], P_TRUE + [0, 0, z]), 3.0)
              for i, z in zip(others, along, strict=True)]
    assert triangulate_bars(frames, segments, [], min_share=0.5) == []
    (bar,) = triangulate_bars(frames, segments, [], min_share=0.5, points=on_bar)
    assert np.linalg.norm(bar.p_O - P_TRUE) < 0.015 and bar.views == tuple(range(10))
    beside = [HandleSighting(s.frame, _project(frames[s.frame], P_TRUE + [0, 0.08, z]), 3.0)
              for s, z in zip(on_bar, along, strict=True)]
    past = [HandleSighting(s.frame, _project(frames[s.frame], P_TRUE + [0, 0, 0.3 * np.sign(z or 1)]), 3.0)
            for s, z in zip(on_bar, along, strict=True)]
    assert triangulate_bars(frames, segments, [], min_share=0.5, points=beside + past) == []
    knob = TriangulatedHandle(P_TRUE + [0, 0, 0.1], (0, 2, 3), 0.5, 10)
    explained = [HandleSighting(s.frame, _project(frames[s.frame], knob.p_O), 3.0) for s in on_bar]
    assert triangulate_bars(frames, segments, [knob], min_share=0.5, points=explained) == []
    with_8 = on_bar + [HandleSighting(8, _project(frames[8], P_TRUE), 3.0)]
    assert triangulate_bars(frames, segments[:2], [], min_share=0.5, points=with_8) == []


def test_points_one_above_the_other_are_one_handle_only_where_one_bar_holds_both():
    """Two points 12 cm one above the other, 3-6 px apart in every view (cameras 4 m away): one
    handle by their projections alone (a bar whose votes split in two); given the views' bar
    segments, two where no segment holds both (two stacked drawers' pulls) and one where an
    upright bar's does. Points 5 cm apart (nearer than `STACKED_M`) stay one either way."""
    frames = _frames(8, 128, distance=4.0)
    pair = [P_TRUE, P_TRUE + np.array([0.0, 0.0, 0.12])]
    found = [s for i, f in enumerate(frames)
             for s in sightings(_votes_map(128, [_project(f, p) for p in pair], spread=1), i)]
    assert len(triangulate_handles(frames, found)) == 1
    assert len(triangulate_handles(frames, found, bars=[])) == 2
    bar = (P_TRUE - [0.0, 0.0, 0.1], P_TRUE + [0.0, 0.0, 0.25])
    segments = [b for i, f in enumerate(frames) for b in bar_sightings(_bar_map(128, f, [bar], 0.0), i)]
    assert len(triangulate_handles(frames, found, bars=segments)) == 1
    near = [P_TRUE, P_TRUE + np.array([0.0, 0.0, 0.05])]
    found = [s for i, f in enumerate(frames)
             for s in sightings(_votes_map(128, [_project(f, p) for p in near], spread=1), i)]
    assert len(triangulate_handles(frames, found, bars=[])) == 1


def test_points_along_one_bar_are_one_handle_at_the_one_nearest_its_middle():
    """A door's 32 cm upright bar whose votes make three points 8 cm apart along its lower half,
    6-7 px apart in some views (more than twice the agreement tolerance): three handles by the
    projections alone; given the views' segments of the bar, one, at the point nearest the bar's
    middle (8 cm above the middle of the points' span), with the views of all three."""
    frames = _frames(8, 128)
    along = [P_TRUE + np.array([0.0, 0.0, dz]) for dz in (-0.08, 0.0, 0.08)]
    found = [s for i, f in enumerate(frames)
             for s in sightings(_votes_map(128, [_project(f, p) for p in along], spread=1), i)]
    assert len(triangulate_handles(frames, found, bars=[])) == 3
    bar = (P_TRUE - [0.0, 0.0, 0.08], P_TRUE + [0.0, 0.0, 0.24])
    segments = [b for i, f in enumerate(frames) for b in bar_sightings(_bar_map(128, f, [bar], 0.0), i)]
    (handle,) = triangulate_handles(frames, found, bars=segments)
    assert np.linalg.norm(handle.p_O - along[2]) < 0.01
    assert handle.views == tuple(range(8))


def test_a_point_near_the_cameras_inside_few_images_is_no_handle():
    """Every view looks at the object: a handle on it is inside all images and kept; a point
    near the first camera, in front of it, is inside few of the others and left out at a share
    of one half."""
    frames = _frames(8, 128)
    eye = frames[0].X_OC[:3, 3]
    near = eye + 0.3 * (np.array([0.0, 0.0, 0.5]) - eye) / np.linalg.norm(np.array([0.0, 0.0, 0.5]) - eye)
    on, off = TriangulatedHandle(P_TRUE, (0, 1, 2), 0.5, 8), TriangulatedHandle(near, (0, 1, 2), 0.5, 8)
    assert in_most_images([on, off], frames, 0.5) == [on]
    assert in_most_images([on, off], frames, 0.0) == [on, off]
