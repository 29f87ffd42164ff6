"""One part of a piece of furniture as the planner and the simulation see it: the part's joint and
handle, the other parts locked shut and present as obstacles, and one opening end to end."""

import numpy as np
import pytest
from pydrake.geometry import Role
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.cli import main
from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects.furniture import sample_furniture
from nfr_drake.objects.handles import GRIP_PART_NAME
from nfr_drake.planning.grasp import handle_waypoints
from nfr_drake.systems.articulation import lock_shut
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import run_task
from nfr_drake.world.obstacles import distance_to_box, object_obstacles


def _first_piece(kind: str, fronts: list[str]):
    """The first piece of `kind` (seeds 0, 1, ...) whose fronts are of the kinds `fronts`."""
    for seed in range(200):
        obj = sample_furniture(np.random.default_rng(seed), kind=kind)
        if [f.kind for f in obj.fronts] == fronts:
            return obj
    raise AssertionError(f"no {kind} with fronts {fronts} in 200 seeds")


@pytest.fixture(scope="module")
def chest():
    return _first_piece("chest", ["drawer", "drawer"])


@pytest.fixture(scope="module")
def door_pair():
    return _first_piece("base_cabinet", ["door", "door"])


def test_scene_object_of_a_part(door_pair):
    X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, 0.4), [0.3, -0.2, 0.0])
    obj = SceneObject.from_articulated_object(door_pair, X_WO, 0.0, part=1)
    front = door_pair.front(1)
    assert (obj.category, obj.joint_name, obj.handle_body_name) == ("closet", "front1_joint", "front1")
    assert obj.locked_joints == ("front0_joint",)
    # The handle point is the centre of the handle's grip geometry in the plant.
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    model = obj.add_to(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    body = plant.GetBodyByName(obj.handle_body_name, model)
    inspector = scene_graph.model_inspector()
    grip = [g for g in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(body.index()), Role.kProximity)
            if inspector.GetName(g).endswith("__f1__" + GRIP_PART_NAME[door_pair.params["handle_style"]])
            or inspector.GetName(g).endswith("__f1__knob")]
    assert len(grip) == 1
    p_W_grip = plant.EvalBodyPoseInWorld(context, body) @ inspector.GetPoseInFrame(grip[0]).translation()
    p_W_handle = plant.EvalBodyPoseInWorld(context, body) @ obj.p_BH
    np.testing.assert_allclose(p_W_handle, p_W_grip, atol=1e-9)
    np.testing.assert_allclose(obj.ground_truth.point("handle", 0.0), p_W_grip, atol=1e-9)
    np.testing.assert_allclose(obj.bar_B, front.grip_axis_M)
    with pytest.raises(NfrDrakeError, match="part 2 is out of range.*2 parts \\(0: door, 1: door\\)"):
        SceneObject.from_articulated_object(door_pair, X_WO, 0.0, part=2)


def test_obstacles_include_the_neighbouring_door(door_pair):
    X_WO = RigidTransform([0.5, 0.0, 0.0])
    boxes = object_obstacles(door_pair, X_WO, 0.0, moving=1)
    names = [b.name for b in boxes]
    assert "front0_slab" in names and "front0_handle" in names
    assert not any(n.startswith("front1_") for n in names)
    # The neighbour's slab covers its panel, the carcass body box every panel of the body.
    slab = boxes[names.index("front0_slab")]
    panel = next(p for p in door_pair.front(0).parts if p.name.endswith("panel"))
    p_W_panel = X_WO @ (door_pair.front(0).X_OM(0.0)[:3, :3] @ panel.p_LP + door_pair.front(0).p_OJ)
    assert distance_to_box(slab, p_W_panel[None])[0] == 0.0
    body = boxes[names.index("carcass_body0")]
    panels = np.array([X_WO @ np.array(p.p_LP) for p in door_pair.base_parts if p.name.startswith("b0_")])
    assert np.all(distance_to_box(body, panels) == 0.0)
    assert len(boxes) <= 8  # one body, a top, a plinth, the other door's slab and handle
    assert len(object_obstacles(door_pair, X_WO, 0.0, moving=1, merge=False)) > 2 * len(boxes)


def test_hand_follows_a_horizontal_bar_on_a_door():
    """A door's horizontal bar: the planner's bar axis is the bar's, turning with the door."""
    for seed in range(300):
        obj = sample_furniture(np.random.default_rng(seed))
        doors = [k for k, f in enumerate(obj.fronts) if f.kind == "door" and f.grip_axis_M == (0.0, 1.0, 0.0)
                 and f.grip_half_length > 0.0]
        if doors:
            break
    front = obj.front(doors[0])
    kt = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0, part=doors[0]).ground_truth
    for waypoint in handle_waypoints(kt, np.array([0.0, 0.3, 0.6])):
        bar_W = front.X_OM(waypoint.q)[:3, :3] @ np.array(front.grip_axis_M)
        assert abs(waypoint.bar_W @ bar_W) == pytest.approx(1.0, abs=1e-3)


def test_locked_drawer_stays_shut(chest):
    """Tipped forward 20 degrees, a free drawer slides out under gravity; a locked one stays shut."""
    tipped = RigidTransform(RollPitchYaw(0.0, np.radians(20.0), 0.0), [0.0, 0.0, 0.3])
    obj = SceneObject.from_articulated_object(chest, tipped, 0.0, part=1)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.002,
                                                      discrete_contact_approximation="sap"), builder)
    model = obj.add_to(plant)
    plant.Finalize()
    simulator = Simulator(builder.Build())
    context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    locked, free = (plant.GetJointByName(n, model) for n in ("front0_joint", "front1_joint"))
    lock_shut(plant, context, [locked])
    simulator.AdvanceTo(0.5)
    assert locked.GetOnePosition(context) == pytest.approx(0.0, abs=1e-6)
    assert free.GetOnePosition(context) > 0.05


def test_open_a_drawer_of_a_chest(chest):
    """Plan with the piece's geometry as obstacles and open drawer 1 while drawer 0 stays locked."""
    obj = SceneObject.from_articulated_object(chest, RigidTransform(), 0.0, part=1)
    outcome = run_task(obj, 1.0)
    assert outcome.success, outcome.planning_error or outcome.simulation.summary()
    assert outcome.simulation.grasped and outcome.simulation.joint_type == "prismatic"


def test_plan_command_lists_the_parts(capsys):
    status = main(["plan", "--category", "furniture", "--seed", "0", "--part", "9"])
    err = capsys.readouterr().err
    assert status == 2
    assert "part 9 is out of range" in err and "0: " in err
