"""The neural field on a user's own model file (`demo --object`, `Scenario.object_file`): the frame O
its carcass gives, its fronts' canonical order, the scenario's checks and the whole pipeline."""

import cv2
import numpy as np
import pytest
from fixtures.user_models import write_models
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.cli import main
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.systems.model_files import drawable_obj, stl_as_obj
from nfr_drake.systems.pipeline import canonical_part, model_file_perception_simulator, run_scenario
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    return {m.name: m for m in write_models(tmp_path_factory.mktemp("user_models"))}


def scenario_of(user_model, **kw) -> Scenario:
    return Scenario(object_file=str(user_model.path), joint=user_model.joint,
                    handle_body=user_model.handle_body, **kw)


@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, 200.0])
def test_the_frame_of_a_model_file_faces_out_of_its_front_at_its_footprints_centre(models, yaw_deg):
    """The base cabinet's carcass spans x -0.3..0.3, y -0.3..0.3 of its file's frame, its door and
    handle in front at +x; placed anywhere, O's +x points out of that front and its origin lies
    under the carcass's centre, on the floor. The bounds hold the handle's middle, which the cameras
    frame; the hand's grip (the bar's axis) stands further out."""
    model = models["base_cabinet_door_on_floor"]
    xyz = [0.4, -0.7, 0.0]
    obj = scenario_of(model, object_xyz=xyz, object_yaw_deg=yaw_deg).model_file_object()
    X_WO, (lo, hi) = obj.category_frame()
    turn = np.radians(yaw_deg)
    np.testing.assert_allclose(X_WO.rotation().col(0), [np.cos(turn), np.sin(turn), 0.0], atol=1e-2)
    np.testing.assert_allclose(X_WO.rotation().col(2), [0.0, 0.0, 1.0], atol=1e-9)
    carcass = np.concatenate([b.X_WB.translation()[None] for b in obj.obstacles])
    np.testing.assert_allclose(X_WO.translation()[:2], xyz[:2], atol=0.03)
    assert abs(X_WO.translation()[2]) < 1e-3 and carcass[:, 2].min() > 0.0
    handle_O = X_WO.inverse() @ obj.handle_middle_W
    assert handle_O[0] > 0.25 and np.all(handle_O >= lo - 1e-9) and np.all(handle_O <= hi + 1e-9)
    grip_O = X_WO.inverse() @ obj.ground_truth.point("handle", 0.0)
    assert grip_O[0] - handle_O[0] == pytest.approx(0.0145, abs=1e-6)  # the bar 4 cm out, 1.1 cm thick


def test_fitted_door_keypoints_are_told_in_the_models_joint_range(models):
    """The base cabinet's door opens 1.75 rad (100 degrees) from shut to open; the fields' q is 90
    degrees per unit. Told in the model's q, its own keypoints (re-sampled at 90 degrees per unit)
    give its handle where the model has it at every q; a drawer's are left as they are."""
    door = scenario_of(models["base_cabinet_door_on_floor"]).model_file_object()
    assert door.joint_range == pytest.approx((0.0, 1.75))
    truth = door.ground_truth
    q_field = np.linspace(0.0, 1.0, 41)
    as_fitted = KeypointTrajectory(truth.category, q_field, truth.names,
                                   truth.at(q_field * (np.pi / 2) / 1.75), 0.0)
    told = door.in_joint_units(as_fitted)
    for q in (0.0, 0.3, 0.6, 0.85):
        np.testing.assert_allclose(told.point("handle", q), truth.point("handle", q), atol=2e-3)
    assert not np.allclose(as_fitted.point("handle", 0.6), truth.point("handle", 0.6), atol=0.02)
    drawer = scenario_of(models["worktop_drawer"]).model_file_object()
    assert drawer.in_joint_units(drawer.ground_truth) is drawer.ground_truth


def test_a_model_without_a_carcass_has_no_frame(models):
    obj = scenario_of(models["base_cabinet_door_on_floor"]).model_file_object()
    with pytest.raises(NfrDrakeError, match="no collision geometry besides its moving part"):
        type(obj).category_frame(type(obj)(**{**obj.__dict__, "obstacles": None}))


def test_the_fronts_of_a_kitchen_counter_in_canonical_order(models):
    """Seen from the front: the pair of doors on the left (left door first), the column of three
    drawers on the right, top to bottom."""
    model = models["kitchen_counter_door_of_a_pair"]
    expected = {"left_door_hinge": 0, "right_door_hinge": 1, "top_slide": 2, "middle_slide": 3,
                "bottom_slide": 4}
    handles = {"left_door_hinge": "left_door_handle", "right_door_hinge": "right_door_handle",
               "top_slide": "top_pull", "middle_slide": "middle_pull", "bottom_slide": "bottom_pull"}
    for joint, index in expected.items():
        obj = Scenario(object_file=str(model.path), joint=joint, handle_body=handles[joint],
                       object_yaw_deg=75.0).model_file_object()
        X_WO, _ = obj.category_frame()
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        instance = obj.add_to(plant)
        plant.Finalize()
        assert canonical_part(plant, scene_graph, instance, obj, X_WO) == index, joint


def test_a_model_file_scenario_is_checked(models):
    model = models["base_cabinet_door_on_floor"]
    with pytest.raises(ConfigError, match="needs joint and handle_body"):
        Scenario(object_file=str(model.path), joint="hinge")
    with pytest.raises(ConfigError, match="task open, perceive alone"):
        scenario_of(model, task="open-and-place")
    with pytest.raises(ConfigError, match="apply to a model file"):
        Scenario(joint="hinge")


def test_a_sliding_door_has_no_field_to_fit(models):
    with pytest.raises(NfrDrakeError, match="no neural field model of sliding doors"):
        run_scenario(scenario_of(models["sliding_door"], model=""))


def test_a_visual_mesh_without_normals_is_drawn_from_a_copy_with_them(models, tmp_path):
    """The wardrobe's handle is an .obj without vertex normals, which Drake's VTK renderer rejects:
    the cameras see a copy with its faces' normals, and the handle (light grey on a brown door) is
    in the photos."""
    model = models["wardrobe_handle_mesh_off_frame"]
    scenario = scenario_of(model, model="models/closet", views=2)
    obj = scenario.model_file_object()
    simulator, perception, notes = model_file_perception_simulator(scenario, obj, obj.category_frame())
    assert len(notes) == 1 and "u_handle.obj" in notes[0] and "normals" in notes[0]
    diagram, context = simulator.get_system(), simulator.get_context()
    sensor = diagram.GetSubsystemByName("nfr_camera_0")
    image = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(context)).data[..., :3]
    image = image.astype(int)
    background = np.abs(image - 255 * np.array(DEFAULT_BACKGROUND_RGB)).max(-1) <= 3
    grey = (np.abs(image - image.mean(-1, keepdims=True)).max(-1) < 12) & (image.mean(-1) > 120) & ~background
    assert grey.sum() >= 20


BOX_FACES = (((0, 1, 3, 2), (-1, 0, 0)), ((4, 6, 7, 5), (1, 0, 0)), ((0, 4, 5, 1), (0, -1, 0)),
             ((2, 3, 7, 6), (0, 1, 0)), ((0, 2, 6, 4), (0, 0, -1)), ((1, 5, 7, 3), (0, 0, 1)))
"""A box's six faces: corner indices (counter-clockwise seen from outside) into `_box_corners`,
and the outward normal."""


def _box_corners(size) -> np.ndarray:
    """The 8 corners (8, 3) of a box of full `size` (m) centred at the origin, corner 4x + 2y + z
    at the +x, +y, +z sides."""
    half = np.asarray(size) / 2
    return np.array([(x, y, z) for x in (-half[0], half[0]) for y in (-half[1], half[1])
                     for z in (-half[2], half[2])])


def _textured_box_obj(folder, size, texture_name: str) -> str:
    """A box (full `size`, m) as an .obj with normals and texture coordinates, its material's
    diffuse map `texture_name`, written into `folder`; its file name."""
    lines = ["mtllib box.mtl", "usemtl skin", *(f"v {x} {y} {z}" for x, y, z in _box_corners(size)),
             "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", *(f"vn {n[0]} {n[1]} {n[2]}" for _, n in BOX_FACES)]
    lines += ["f " + " ".join(f"{v + 1}/{k + 1}/{i + 1}" for k, v in enumerate(f))
              for i, (f, _) in enumerate(BOX_FACES)]
    (folder / "box.obj").write_text("\n".join(lines) + "\n")
    (folder / "box.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {texture_name}\n")
    return "box.obj"


def test_a_door_with_a_jpeg_texture_is_photographed_with_it(models, tmp_path):
    """The base cabinet's door drawn as a mesh with a JPEG texture, half green, half blue: the
    photos show both colours (not the white, misdrawn face the renderer makes of a JPEG map)."""
    texture = np.zeros((16, 16, 3), np.uint8)
    texture[:, :8], texture[:, 8:] = (40, 200, 40), (200, 120, 20)  # BGR: green, then blue
    cv2.imwrite(str(tmp_path / "paint.jpg"), texture)
    mesh = _textured_box_obj(tmp_path, (0.018, 0.596, 0.721), "paint.jpg")
    urdf = models["base_cabinet_door_on_floor"].path.read_text().replace(
        '<visual><origin xyz="0.009 0.3 0.3595" rpy="0 0 0"/><geometry><box size="0.018 0.596 0.721"/>',
        f'<visual><origin xyz="0.009 0.3 0.3595" rpy="0 0 0"/><geometry><mesh filename="{mesh}"/>', 1)
    assert mesh in urdf
    (tmp_path / "cabinet.urdf").write_text(urdf)
    scenario = Scenario(object_file=str(tmp_path / "cabinet.urdf"), joint="hinge", handle_body="handle",
                        model="models/closet", views=4)
    obj = scenario.model_file_object()
    simulator, _, notes = model_file_perception_simulator(scenario, obj, obj.category_frame())
    assert len(notes) == 1 and "paint.jpg" in notes[0]
    green = blue = 0
    for i in range(4):
        sensor = simulator.get_system().GetSubsystemByName(f"nfr_camera_{i}")
        image = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(simulator.get_context()))
        rgb = image.data[..., :3].astype(int)
        green += int(((rgb[..., 1] > rgb[..., 0] + 40) & (rgb[..., 1] > rgb[..., 2] + 40)).sum())
        blue += int(((rgb[..., 2] > rgb[..., 0] + 40) & (rgb[..., 2] > rgb[..., 1] + 20)).sum())
    assert green > 200 and blue > 200, (green, blue)


def _stl_box(size) -> bytes:
    """A box (full `size`, m) as a binary STL, its triangles wound outward."""
    corners = _box_corners(size)
    triangles = np.array([corners[list(t)] for q, _ in BOX_FACES
                          for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    records = np.zeros(len(triangles), np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    records["v"] = triangles
    return b"\0" * 80 + np.uint32(len(triangles)).tobytes() + records.tobytes()


def test_a_door_drawn_as_an_stl_is_photographed(models, tmp_path):
    """Drake's renderer ignores an STL visual (a model exported for ROS would be photographed
    without its door, the carcass open): the cameras see an .obj copy, so the door (grey, the
    carcass orange) fills a good part of the photos."""
    (tmp_path / "door.stl").write_bytes(_stl_box((0.018, 0.596, 0.721)))
    urdf = models["base_cabinet_door_on_floor"].path.read_text().replace(
        '<visual><origin xyz="0.009 0.3 0.3595" rpy="0 0 0"/><geometry><box size="0.018 0.596 0.721"/>',
        '<visual><origin xyz="0.009 0.3 0.3595" rpy="0 0 0"/><geometry><mesh filename="door.stl"/>', 1)
    assert "door.stl" in urdf
    (tmp_path / "cabinet.urdf").write_text(urdf)
    scenario = Scenario(object_file=str(tmp_path / "cabinet.urdf"), joint="hinge", handle_body="handle",
                        model="models/closet", views=4)
    obj = scenario.model_file_object()
    simulator, _, notes = model_file_perception_simulator(scenario, obj, obj.category_frame())
    assert len(notes) == 1 and "door.stl" in notes[0] and "STL" in notes[0]
    grey = 0
    for i in range(4):
        sensor = simulator.get_system().GetSubsystemByName(f"nfr_camera_{i}")
        rgb = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(simulator.get_context()))
        rgb = rgb.data[..., :3].astype(int)
        background = np.abs(rgb - 255 * np.array(DEFAULT_BACKGROUND_RGB)).max(-1) <= 3
        grey += int(((np.ptp(rgb, axis=-1) < 12) & (rgb.mean(-1) > 60) & ~background).sum())
    assert grey > 2000, grey


def test_an_stl_becomes_an_obj_with_its_triangles_normals(tmp_path):
    """Binary and ASCII STL: the .obj copy has the triangles' vertices and each one's normal from
    its winding (+z for a triangle counter-clockwise seen from above)."""
    ascii_stl = ("solid t\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                 "endloop\nendfacet\nendsolid t\n")
    (tmp_path / "a.stl").write_text(ascii_stl)
    (tmp_path / "b.stl").write_bytes(_stl_box((1.0, 1.0, 1.0)))
    lines = stl_as_obj(tmp_path / "a.stl", tmp_path).read_text().splitlines()
    assert lines == ["v 0 0 0", "v 1 0 0", "v 0 1 0", "vn 0.000000 0.000000 1.000000", "f 1//1 2//1 3//1"]
    box = stl_as_obj(tmp_path / "b.stl", tmp_path).read_text().splitlines()
    assert sum(line.startswith("v ") for line in box) == 36
    assert sum(line.startswith("f ") for line in box) == 12


def test_an_obj_without_normals_gets_its_faces_normals(tmp_path):
    """A unit square in z = 0, two triangles wound counter-clockwise seen from +z, with texture
    coordinates on one face: the copy's faces point at one normal each, +z."""
    path = tmp_path / "square.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 3 4\n")
    copy, changed = drawable_obj(path, tmp_path)
    assert changed == ["no vertex normals"]
    lines = copy.read_text().splitlines()
    assert [line for line in lines if line.startswith("vn")] == ["vn 0.000000 0.000000 1.000000"] * 2
    assert [line for line in lines if line.startswith("f")] == ["f 1/1/1 2/1/1 3/1/1", "f 1//2 3//2 4//2"]
    assert drawable_obj(copy, tmp_path) is None
    # The copies' folder is made when missing (a fresh machine's temporary folder).
    fresh, _ = drawable_obj(path, tmp_path / "not" / "yet")
    assert fresh.read_text() == copy.read_text()


def test_an_obj_with_a_jpeg_texture_is_drawn_from_png_copies(tmp_path):
    """A JPEG diffuse map, which Drake's VTK renderer does not draw: the copy's material library
    names a PNG of the same picture, and the PNG map too is copied beside it."""
    folder = tmp_path / "model"
    folder.mkdir()
    picture = np.zeros((8, 8, 3), np.uint8)
    picture[:, 4:] = (20, 120, 220)
    cv2.imwrite(str(folder / "wood.jpg"), picture)
    cv2.imwrite(str(folder / "steel.png"), picture)
    (folder / "cab.mtl").write_text("newmtl wood\nKd 1 1 1\nmap_Kd wood.jpg\n"
                                    "newmtl steel\nmap_Kd steel.png\n")
    obj = folder / "cab.obj"
    obj.write_text("mtllib cab.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\n"
                   "usemtl wood\nf 1/1/1 2/1/1 3/1/1\n")
    copy, changed = drawable_obj(obj, tmp_path)
    assert changed == ["a texture that is not a PNG (wood.jpg)"]
    (library,) = [line.split()[1] for line in copy.read_text().splitlines() if line.startswith("mtllib")]
    mtl = copy.parent / library
    maps = [mtl.parent / line.split()[-1] for line in mtl.read_text().splitlines()
            if line.startswith("map_Kd")]
    assert all(m.suffix == ".png" and m.parent == mtl.parent for m in maps)
    np.testing.assert_array_equal(cv2.imread(str(maps[0])), cv2.imread(str(folder / "wood.jpg")))
    np.testing.assert_array_equal(cv2.imread(str(maps[1])), cv2.imread(str(folder / "steel.png")))
    assert drawable_obj(folder / "cab.obj", tmp_path) is not None  # the original still names the JPEG


def test_a_drawer_of_a_model_file_is_opened_with_the_furniture_fields_keypoints(models, tmp_path, capsys):
    """`demo --object` by default fits models/furniture: the drawer under a worktop is found (its
    handle within a few centimetres) and pulled open in simulation on the model."""
    model = models["worktop_drawer"]
    status = main(["demo", "--object", str(model.path), "--joint", model.joint, "--handle-body",
                   model.handle_body, "--threads", "1", "--replay", str(tmp_path / "r.html")])
    out = capsys.readouterr().out
    handle_cm = float(out.split("handle ")[1].split(" cm from the model's")[0])
    assert handle_cm < 5.0 and status == 0 and "SUCCESS" in out, out


def test_a_model_files_pose_can_be_estimated_from_its_photos(models):
    """With `object_pose` "estimated" the cameras stand around a coarse look at the model and its
    frame O is estimated from the photos' masks; the outcome reports how far that lies from the
    frame its carcass gives (a few cm and degrees on the plain base cabinet)."""
    scenario = scenario_of(models["base_cabinet_drawn_open"], model="models/closet", object_pose="estimated",
                           min_confidence=1.0, object_xyz=[0.3, -0.2, 0.0], object_yaw_deg=25.0)
    outcome = run_scenario(scenario)
    assert outcome.task is None and outcome.refused  # refused at P >= 1: nothing planned
    assert outcome.pose_error is not None
    assert outcome.pose_error[0] < 5.0 and outcome.pose_error[1] < 5.0, outcome.pose_error


def test_a_door_of_a_model_file_is_perceived_and_opened_with_the_fitted_keypoints(models, tmp_path, capsys):
    """`demo --object --model models/closet`: photographed alone, fitted with the closet model,
    planned on its fitted keypoints and simulated on the model; the handle is found within a few
    centimetres (the file's door is plain, one colour, unlike the training closets), so the door
    opens."""
    model = models["base_cabinet_door_on_floor"]
    args = ["demo", "--object", str(model.path), "--joint", model.joint, "--handle-body", model.handle_body,
            "--model", "models/closet", "--threads", "1", "--replay", str(tmp_path / "r.html")]
    status = main([*args, "--min-confidence", "0"])
    out = capsys.readouterr().out
    handle_cm = float(out.split("handle ")[1].split(" cm from the model's")[0])
    assert handle_cm < 5.0, out
    assert status == 0 and "SUCCESS" in out, out
    # Planned only above the model's calibrated threshold: refused (exit 2, one line) below it.
    p = float(out.split("P(handle within 2 cm) ")[1].split()[0])
    status = main([*args, "--min-confidence", f"{p + 0.01:.2f}"])
    out = capsys.readouterr().out
    assert status == 2 and "refused" in out and "SUCCESS" not in out, out
