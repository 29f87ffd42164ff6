"""Furniture: keypoints and labels agree with the plant's geometry for every kind of front."""

import math
from collections import Counter

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.objects import SEED_DOMAIN_TRAIN, SemanticClass, object_rng, sample_object, to_sdformat
from nfr_drake.objects.articulated import MAX_FRONTS
from nfr_drake.objects.fronts import TRAVEL_FRACTION
from nfr_drake.objects.furniture import KINDS, FurnitureRanges, canonical_order, sample_furniture
from nfr_drake.objects.handles import GRIP_PART_NAME
from nfr_drake.objects.plant import self_penetrations


def _pieces(n, seed=11):
    return [sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, seed, i)) for i in range(n)]


def _panel_span(front):
    """(y0, y1, z0, z1) of the door or drawer panel at q = 0, in O."""
    panel = next(p for p in front.parts if p.name.endswith("__panel"))
    y, z = front.p_OJ[1] + panel.p_LP[1], front.p_OJ[2] + panel.p_LP[2]
    return y - panel.size[1] / 2, y + panel.size[1] / 2, z - panel.size[2] / 2, z + panel.size[2] / 2


def _front_type(obj, k):
    """A name for the kind of front k: door single or pair, left or right hinge; drawer in a stack,
    drawer over a door, drawer alone."""
    f = obj.front(k)
    y0, y1, z0, z1 = _panel_span(f)
    if f.kind == "door":
        left = f.axis_O[2] < 0
        pair = any(g.kind == "door" and g.axis_O != f.axis_O and np.allclose(_panel_span(g)[2:], (z0, z1))
                   and 0 < (_panel_span(g)[0] - y1 if left else y0 - _panel_span(g)[1]) < 0.01
                   for g in obj.fronts)
        return f"door_{'pair' if pair else 'single'}_{'left' if left else 'right'}"
    column = [g for g in obj.fronts if g is not f and abs(_panel_span(g)[0] - y0) < 1e-6]
    if any(g.kind == "door" and _panel_span(g)[3] < z0 for g in column):
        return "drawer_over_door"
    return "drawer_stack" if any(g.kind == "drawer" for g in column) else "drawer_single"


def _grip_geometry(loaded, k):
    for name in GRIP_PART_NAME.values():
        try:
            return loaded.geometry_pose(f"handle__f{k}__{name}")
        except KeyError:
            continue
    raise KeyError(k)


# Three pieces of every kind: together they show every type of front (the first test checks).
PIECES = [sample_furniture(np.random.default_rng([3, i]), kind=KINDS[i % len(KINDS)]) for i in range(27)]


def test_every_kind_and_front_type_is_sampled():
    kinds = Counter(o.params["kind"] for o in _pieces(150))
    assert set(kinds) == set(KINDS)
    types = {_front_type(o, k) for o in PIECES for k in range(o.num_fronts)}
    assert {"door_single_left", "door_single_right", "door_pair_left", "door_pair_right",
            "drawer_stack", "drawer_over_door"} <= types


@pytest.mark.parametrize("index", range(len(PIECES)))
def test_keypoints_agree_with_the_plant(index, load_object):
    obj = PIECES[index]
    loaded = load_object(obj)
    assert loaded.plant.num_positions() == obj.num_fronts
    for k, front in enumerate(obj.fronts):
        joint = loaded.plant.GetJointByName(front.joint_name, loaded.model)
        assert joint.position_upper_limits()[0] == pytest.approx(front.joint_upper, rel=1e-5)
        mass, _, inertia = front.inertia()
        assert mass > 0 and np.all(np.linalg.eigvalsh(inertia) > 0)
        for q in (0.0, 0.6, 1.0):
            qs = np.zeros(obj.num_fronts)
            qs[k] = q
            loaded.set_q(qs)
            kp = obj.front_keypoints(qs)[k]
            np.testing.assert_allclose(kp["handle"], _grip_geometry(loaded, k)[:3, 3], atol=1e-6)
            panel = loaded.geometry_pose(f"moving__f{k}__panel")
            if front.kind == "door":
                X_WJ = joint.frame_on_parent().CalcPoseInWorld(loaded.plant_context).GetAsMatrix4()
                axis_W = X_WJ[:3, :3] @ joint.revolute_axis()
                half_h = next(p.size[2] for p in front.parts if p.name.endswith("panel")) / 2
                for name, dz in (("hinge_top", half_h), ("hinge_bottom", -half_h)):
                    assert np.linalg.norm(np.cross(kp[name] - X_WJ[:3, 3], axis_W)) < 1e-7
                    assert kp[name][2] == pytest.approx(panel[2, 3] + dz, abs=1e-7)
                lo, hi = obj.base_bounds()
                assert np.all(kp["goal"] > lo) and np.all(kp["goal"] < hi)
                assert kp["goal"][0] < front.p_OJ[0]  # behind the door
            else:
                box = loaded.geometry_pose(f"moving__f{k}__box_bottom")
                wall = next(p.size[2] for p in front.parts if p.name.endswith("box_bottom"))
                np.testing.assert_allclose(kp["goal"], box[:3, 3] + [0, 0, wall / 2], atol=1e-9)
                travel = kp["handle"] - front.keypoints(0.0)["handle"]
                np.testing.assert_allclose(travel, q * front.joint_upper * np.asarray(front.axis_O),
                                           atol=1e-9)
        # The handle stands out of the front, towards +x.
        face_x = max(p.p_LP[0] + p.size[0] / 2 for p in front.parts if p.semantic == SemanticClass.MOVING
                     and p.shape == "box" and "box_" not in p.name)
        assert front.moving_keypoints["handle"][0] > face_x
        if front.kind == "drawer":
            depth = next(p.size[0] for p in front.parts if p.name.endswith("box_bottom"))
            assert front.joint_upper == pytest.approx(TRAVEL_FRACTION * depth)


def test_fronts_are_in_canonical_order_and_within_the_ranges():
    ranges = FurnitureRanges()
    for obj in _pieces(60):
        keys = [_panel_span(f)[::3] for f in obj.fronts]
        assert keys == sorted(keys, key=lambda r: (round(r[0] * 1000), -round(r[1] * 1000)))
        assert [f.link_name for f in obj.fronts] == [f"front{k}" for k in range(obj.num_fronts)]
        assert 1 <= obj.num_fronts <= MAX_FRONTS
        p = obj.params
        assert ranges.width[0] <= p["width"] <= ranges.width[1]
        assert ranges.height[0] <= p["height"] - p["mount"] and p["height"] <= ranges.height[1]
    assert canonical_order([]) == []


def test_no_self_collision_shut_or_with_one_front_open():
    for obj in _pieces(20, seed=12):
        assert self_penetrations(obj, 0.0) == []
    for obj in PIECES[:9]:
        for k in range(obj.num_fronts):
            q = np.zeros(obj.num_fronts)
            q[k] = 1.0
            assert self_penetrations(obj, q) == [], (obj.params["kind"], k)


def test_same_stream_gives_the_same_piece():
    a, b = (sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, 4, 2)) for _ in range(2))
    c = sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, 4, 3))
    assert to_sdformat(a) == to_sdformat(b) and a.params == b.params
    assert to_sdformat(a) != to_sdformat(c)


def test_rendered_part_indices_belong_to_their_fronts():
    """From straight ahead every front is seen; the pixel at each panel's centre carries its index."""
    camera = PinholeCamera.from_fov(96, 96, math.radians(45))
    for obj in (PIECES[0], PIECES[3], PIECES[4]):  # base cabinet, chest, desk
        lo, hi = obj.base_bounds()
        target = (lo + hi) / 2
        X_OC = look_at(target + [3.2 * max(hi - lo), 0.0, 0.0], target)
        view = ObjectRenderer(obj, camera).render(0.0, X_OC)
        assert set(np.unique(view.part)) == {-1, *range(obj.num_fronts)}
        assert np.all(view.part[view.label == SemanticClass.CARCASS] == -1)
        assert np.all(view.part[view.label >= SemanticClass.MOVING] >= 0)
        X_CO = np.linalg.inv(X_OC)
        for k, front in enumerate(obj.fronts):
            panel = next(p for p in front.parts if p.name.endswith("__panel"))
            p_O = front.X_OM(0.0)[:3, :3] @ panel.p_LP + front.p_OJ + [panel.size[0] / 2, 0, 0]
            p_C = X_CO[:3, :3] @ p_O + X_CO[:3, 3]
            u, v = camera.fx * p_C[0] / p_C[2] + camera.cx, camera.fy * p_C[1] / p_C[2] + camera.cy
            window = view.part[int(v) - 1:int(v) + 2, int(u) - 1:int(u) + 2]
            assert k in window, (obj.params["kind"], k)


def test_textures_are_pngs_made_once_from_kind_and_seed(tmp_path, monkeypatch):
    import cv2

    from nfr_drake.objects.textures import TEXTURE_KINDS, texture_image, texture_uri

    monkeypatch.setenv("NFR_DRAKE_TEXTURE_DIR", str(tmp_path))
    for kind in TEXTURE_KINDS:
        uri = texture_uri(kind, 3)
        path = tmp_path / f"{kind}_00000003.png"
        assert uri == path.resolve().as_uri() and path.is_file()
        image = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(image, texture_image(kind, 3))
        assert image.std() > 1.0  # a pattern, not a flat colour
    assert not np.array_equal(texture_image("wood", 3), texture_image("wood", 4))


def test_room_above_every_grip():
    """No carcass part hangs over a grip within 4 cm above it (an open gripper's finger, or a
    hand's): an edge pull on the top edge of a drawer under an overhanging top could not be held."""
    for i in range(100):
        obj = sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, 7, i))
        for k, front in enumerate(obj.fronts):
            p = front.keypoints(0.0)["handle"]
            for part in obj.base_parts:
                if part.shape != "box":
                    continue
                half = np.divide(part.size, 2)
                lo, hi = np.subtract(part.p_LP, half), np.add(part.p_LP, half)
                over = lo[0] <= p[0] <= hi[0] and lo[1] <= p[1] <= hi[1] and p[2] < lo[2] <= p[2] + 0.04
                assert not over, f"piece {i} ({obj.params['kind']}) front {k}: {part.name} above"
