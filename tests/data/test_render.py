"""Drake renders: label classes where expected; the camera convention matches our intrinsics."""

import math

import cv2
import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution, look_at
from nfr_drake.data.render import RENDERER_NAME, ObjectRenderer, drake_camera_info
from nfr_drake.objects import SEED_DOMAIN_TRAIN, SemanticClass, object_rng, sample_object

SIZE = 128


def _project(camera: PinholeCamera, X_OC: np.ndarray, p_O: np.ndarray) -> np.ndarray:
    """Continuous pixel coordinates (u, v) of p_O; the top-left pixel's centre is (0.5, 0.5)."""
    X_CO = np.linalg.inv(X_OC)
    p_C = X_CO[:3, :3] @ p_O + X_CO[:3, 3]
    return np.array([camera.fx * p_C[0] / p_C[2] + camera.cx, camera.fy * p_C[1] / p_C[2] + camera.cy])


def _unproject(camera, X_OC, depth):
    """Points in O of every pixel with a finite depth: (N, 3), and their (row, col) indices."""
    rows, cols = np.nonzero(np.isfinite(depth))
    z = depth[rows, cols]
    x = (cols + 0.5 - camera.cx) / camera.fx * z
    y = (rows + 0.5 - camera.cy) / camera.fy * z
    p_C = np.stack([x, y, z], 1)
    return p_C @ X_OC[:3, :3].T + X_OC[:3, 3], rows, cols


@pytest.fixture(scope="module")
def closet():
    for i in range(50):
        obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 11, i))
        if obj.params["handle_type"] == "bar":
            return obj
    raise AssertionError("no bar-handled closet in 50 seeds")


@pytest.fixture(scope="module")
def camera():
    return PinholeCamera.from_fov(SIZE, SIZE, math.radians(50))


def test_depth_unprojects_onto_the_door_front_surface(closet, camera):
    """A known plane: door pixels at q = 0, unprojected with our K and X_OC, lie on x = D/2 + td."""
    renderer = ObjectRenderer(closet, camera)
    X_OC = look_at(np.array([1.6, 0.3, 0.9]), closet.look_at_target())
    view = renderer.render(0.0, X_OC)
    points, rows, cols = _unproject(camera, X_OC, view.depth)
    door = view.label[rows, cols] == SemanticClass.MOVING
    assert door.sum() > 500
    front_x = closet.params["depth"] / 2 + closet.params["door_thickness"]
    # Away from the door's silhouette, where a pixel may straddle two surfaces.
    assert np.median(np.abs(points[door, 0] - front_x)) < 2e-3
    assert np.percentile(np.abs(points[door, 0] - front_x), 90) < 5e-3


def test_keypoints_project_onto_their_classes(closet, camera):
    renderer = ObjectRenderer(closet, camera)
    rng = np.random.default_rng(0)
    hits = 0
    for X_OC in CameraDistribution(azimuth_deg=(-30, 30)).sample(rng, 6, closet.look_at_target()):
        view = renderer.render(0.0, X_OC)
        u, v = _project(camera, X_OC, closet.keypoints(0.0)["handle"])
        r, c = int(v), int(u)  # the pixel containing the continuous coordinate
        patch = view.label[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
        hits += SemanticClass.HANDLE in patch
        # The door's centre at q = 0 is door; a point beyond the object is background.
        door_centre = np.array([closet.params["depth"] / 2 + 0.01, 0.0, closet.params["height"] / 2])
        u, v = _project(camera, X_OC, door_centre)
        assert view.label[int(v), int(u)] in (SemanticClass.MOVING, SemanticClass.HANDLE)
        assert view.label[0, 0] == SemanticClass.BACKGROUND
    assert hits >= 5


def test_all_classes_appear_and_carcass_shows_when_door_is_open(closet, camera):
    renderer = ObjectRenderer(closet, camera)
    X_OC = look_at(np.array([1.5, 0.0, 0.8]), closet.look_at_target())
    closed, opened = renderer.render(0.0, X_OC), renderer.render(1.0, X_OC)
    assert set(np.unique(closed.label)) == {0, 1, 2, 3}
    # Opening the door uncovers the carcass's inside, seen straight from the front.
    assert (opened.label == SemanticClass.CARCASS).sum() > 3 * (closed.label == SemanticClass.CARCASS).sum()
    assert closed.rgb.shape == (SIZE, SIZE, 3) and closed.rgb.dtype == np.uint8
    assert np.isinf(closed.depth[0, 0]) and np.isfinite(closed.depth[SIZE // 2, SIZE // 2])


def test_drawer_moves_out_in_depth():
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 11, 0))
    camera = PinholeCamera.from_fov(64, 64, math.radians(50))
    renderer = ObjectRenderer(obj, camera)
    X_OC = look_at(np.array([1.6, 0.0, 0.9]), obj.look_at_target())
    closed, opened = renderer.render(0.0, X_OC), renderer.render(1.0, X_OC)
    moving = lambda v: v.depth[v.label == SemanticClass.MOVING].min()  # noqa: E731
    # The front comes towards the camera by about the travel times cos(elevation).
    assert moving(closed) - moving(opened) > 0.6 * obj.joint_upper


def test_spheres_render_where_the_intrinsics_project_them():
    """Sub-pixel check of `drake_camera_info`: the silhouette centroids of small spheres in an
    off-centre, non-square camera match their centres' projections to the silhouettes'
    quantisation (the renders were once shifted by -0.5 px in u and v)."""
    from pydrake.geometry import (
        ClippingRange,
        DepthRange,
        DepthRenderCamera,
        MakeRenderEngineVtk,
        RenderCameraCore,
        RenderEngineVtkParams,
        Sphere,
    )
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.sensors import RgbdSensor

    camera = PinholeCamera(fx=70.0, fy=72.0, cx=43.3, cy=27.8, width=90, height=60)
    centres = np.array([[0.0, 0.0, 1.0], [0.2, 0.1, 1.1], [-0.25, -0.12, 1.3]])  # camera frame
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    scene_graph.AddRenderer(RENDERER_NAME, MakeRenderEngineVtk(RenderEngineVtkParams()))
    for i, p in enumerate(centres):
        plant.RegisterVisualGeometry(plant.world_body(), RigidTransform(p), Sphere(0.08),
                                     f"sphere{i}", np.array([0.8, 0.2, 0.2, 1.0]))
    plant.Finalize()
    core = RenderCameraCore(RENDERER_NAME, drake_camera_info(camera), ClippingRange(0.05, 10.0),
                            RigidTransform())
    sensor = builder.AddSystem(RgbdSensor(
        parent_id=scene_graph.world_frame_id(), X_PB=RigidTransform(),
        depth_camera=DepthRenderCamera(core, DepthRange(0.05, 10.0))))
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    diagram = builder.Build()
    context = sensor.GetMyContextFromRoot(diagram.CreateDefaultContext())
    depth = np.array(sensor.depth_image_32F_output_port().Eval(context).data)[..., 0]
    count, blobs = cv2.connectedComponents(np.isfinite(depth).astype(np.uint8))
    assert count == 1 + len(centres)
    projected = centres[:, :2] / centres[:, 2:] * [camera.fx, camera.fy] + [camera.cx, camera.cy]
    errors = []
    for k in range(1, count):
        rows, cols = np.nonzero(blobs == k)
        centroid = np.array([cols.mean() + 0.5, rows.mean() + 0.5])
        nearest = np.argmin(np.linalg.norm(projected - centroid, axis=1))
        errors.append(centroid - projected[nearest])
    errors = np.array(errors)
    # A silhouette's centroid is quantised to ~0.1 px; a shifted principal point moves all alike.
    assert np.abs(errors).max() < 0.2, errors
    assert np.abs(errors.mean(0)).max() < 0.1, errors
