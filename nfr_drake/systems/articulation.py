"""Simulating a planned grasp-and-articulate motion on the true object (docs/SIMULATION.md).

A discrete MultibodyPlant (SAP) holds the floor, the arm (on a pedestal welded to the world when the
plan raised its base) and the object; the object's other joints (`SceneObject.locked_joints`) are
locked shut in the context. The arm's joints are PD
controlled inside the plant (implicit PD of the actuators) towards the plan, with gravity
compensation as feed-forward. Once the hand holds the handle the arm turns compliant
(`SimulationConfig.grasped_stiffness`, `CompliantCommand`): the true joint of the object, not the
predicted path, then decides where the handle goes, as with an impedance-controlled arm. The
grasp is a ball constraint between the tool frame's origin and a grip point of the true handle
(optionally two along the bar: a hinge about it). Fingers can close anywhere on a bar's free
stretch (`SceneObject.grip_half_length`), so grip points are laid along it every `grip_spacing`;
a knob has one. All are inactive until the hand rests on the handle; then the grip point nearest
the tool origin is switched on through the context, only if it lies inside the open gripper
(`capture_half_extents`, in the tool frame); after a miss the hand opens and tries again
further along the approach, then short of the planned grasp (`SimulationConfig.regrasps`,
`try_steps`, `PlanTries`).
`SimulationConfig.grasp = "contact"` instead closes the fingers on the handle with a set force and
lets friction hold it (compliant hydroelastic pads on a rigid hydroelastic handle), the arm stiff
throughout, as on a real robot. A drawer's pull
planned to the end of travel ends at its stop: by contact, a second pull past the planned end
(`SecondPull`); with the constraint, a guarded pull along the plan's line that stops when the arm
senses the stop (`PullToStop`).
"""

from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    CollisionFilterDeclaration,
    GeometrySet,
    Meshcat,
    MeshcatVisualizer,
    ProximityProperties,
    RoleAssign,
)
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import JointActuatorIndex, PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.trajectories import PiecewisePolynomial

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects.fronts import DOOR_OPENING
from nfr_drake.systems.corrections import (
    door_turn_offset,
    felt_door_turn_offset,
    felt_line,
    fingers_hold,
    regrasp_step,
    tool_pose_and_jacobian,
    tool_step,
)
from nfr_drake.systems.keypoints import AddKeypointTrajectorySource
from nfr_drake.systems.scene_objects import SceneObject, set_joint_value
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.plan import PlanResult
from nfr_drake.world.robot import (
    FINGER_JOINTS,
    FINGER_OPEN,
    HAND_BODIES,
    NUM_ARM_JOINTS,
    PEDESTAL_NAME,
    TOOL_FRAME,
    add_floor,
    add_panda,
    add_pedestal,
)

# Implicit PD gains of the actuators (arm joints 1-7, then the two fingers).
_KP = np.array([1500.0, 1500.0, 1500.0, 1500.0, 400.0, 400.0, 200.0, 300.0, 300.0])
_KD = np.array([120.0, 120.0, 100.0, 100.0, 25.0, 20.0, 10.0, 10.0, 10.0])
_G = np.array([0.0, 0.0, -9.81])
GRASPS = ("constraint", "contact")
PAD_MODULUS = 1e6
"""Hydroelastic modulus of the finger pads in a contact grasp, Pa (a rubber-like pad)."""
CONTACT_TURN_MAX_HINGE_GAP = 0.02
"""The contact grasp's `SimulationConfig.turn_max_hinge_gap`, m. On the development closets (seed
901, 0-23) the four doors turned with felt hinges 2.2-4.5 cm off ended 2.7-7.4 degrees off, the 20
up to 1.6 cm off at most 2.1 (docs/SIMULATION.md); over 100 unseen closets fitted by the
field, the 94 with gaps under 2.4 cm ended at most 2.4 degrees off after the turn, the six over
2.4 cm (a bar slid 1.6-1.8 cm along the fingers) 2.2-5.4 degrees (docs/PLACE.md, "The turn
measured by a hand that slid")."""
JOINT_FRICTION = {"prismatic": 3.0, "revolute": 0.3}
"""Coulomb friction of the articulated joint by its type, N (a drawer's runners) or N m (a door's
hinges). Without it a drawer, on its 2 N s/m of damping alone, slid 2 cm back in from the nudge
of an item set down in it."""


@dataclass
class SimulationConfig:
    """Options of `simulate_articulation`."""

    time_step: float = 0.002
    dwell: float = 0.5
    """Time the hand rests on the handle while the fingers close, s. Half-way the fingers close:
    the grasp holds if the grip point is then inside `capture_half_extents`, else it is a miss
    (`regrasps`)."""
    settle: float = 0.5
    """Time after the plan ends before the outcome is measured, s."""
    capture_half_extents: tuple[float, float, float] = (0.02, 0.03, 0.02)
    """The grasp holds only if the grip point lies in this box about the tool origin, m, along the
    tool frame's x (the bar axis), y (the fingers' closing axis) and z (the approach). Closing
    fingers 4 cm either side of the tool (`FINGER_OPEN`) centre a bar of radius <= 1.2 cm found
    up to 3 cm to either side; along the approach and the bar the finger pads span about 2 cm."""
    grip_spacing: float = 0.005
    """Spacing of the candidate grip points along a bar, m."""
    grasp_half_span: float = 0.0
    """0: one ball constraint at the grasp point (a point grasp, rotations free). > 0: two, this far
    either side of it along the bar (a hinge about the bar), m."""
    finger_closed: float = 0.012
    """Finger opening (each) when closed on a handle, m."""
    sample_period: float = 0.02
    """Period of the recorded outcome samples, s."""
    revolute_tolerance: float = float(np.radians(5.0))
    prismatic_tolerance: float = 0.02
    drift_tolerance: float = 0.02
    grasped_stiffness: float = 0.1
    """Fraction of the arm's PD gains kept from the grasp on (1 = as stiff as during the approach).
    A stiff arm drags the held handle along the planned path, which is off the true one by the
    keypoint error; a compliant one lets the object's joint guide the hand. Constraint grasp only."""
    grasp: str = "constraint"
    """"constraint": the hand holds the grip point with a ball constraint switched on as the
    fingers close (hand-handle contact filtered out). "contact": the fingers squeeze the handle
    (`squeeze_force`) and friction holds it (compliant hydroelastic pads, `hydroelastic_grip`; no
    constraint, no filter); the arm keeps its full stiffness throughout (`grasped_stiffness` is
    not used)."""
    squeeze_force: float = 40.0
    """Contact grasp: each finger's PD pushes this hard on what it closes on, N (its target lies
    `squeeze_force / Kp` past the closed pads; the Panda hand's continuous force is 70 N)."""
    second_pull: bool = True
    """Contact grasp, a straight planned pull (a drawer): once the pull has settled, the robot
    compares the tool's travel since the fingers closed, from its own joint positions (forward
    kinematics), with the planned handle travel, and pulls again along the plan's line by the
    shortfall (`SecondPull`) when it exceeds `second_pull_min` (at most `second_pull_max`)."""
    second_pull_time: float = 1.5
    """Time the second pull takes (its ramp, 40%, settling to 80%, then held), s; taken whether or
    not it pulls."""
    second_pull_min: float = 0.002
    second_pull_max: float = 0.02
    """The smallest shortfall pulled again and the most pulled, m: the hand cannot tell a bar
    slipping in its fingers from a drawer at its stop, and 3 cm past the stop dragged bars out."""
    pull_to_stop: float = 0.03
    """A pull planned to the end of travel (q 1, fully open): the second pull goes on this far
    past the planned end (m), the arm compliant (`pull_to_stop_stiffness`), so the drawer's stop,
    not the keypoints' predicted travel, ends it; then the arm holds where it came to rest."""
    pull_to_stop_stiffness: float = 0.1
    """Fraction of the arm's PD gains during a pull to the stop (about 600 N/m at the tool: some
    20 N against the stop for 3 cm past it, under the grip's 80 N of friction)."""
    guarded_pull: float = 0.3
    """Constraint grasp, a straight pull planned to the end of travel (q 1, a drawer): once the
    planned pull has settled, the command goes on along the plan's line by at most this (m),
    the arm compliant (`grasped_stiffness`), until the force its lag implies reaches
    `guarded_pull_force` (`PullToStop`): the drawer's stop, not the keypoints' predicted travel,
    ends the pull. 0: none (the pull ends at the plan's end). 0.3 m: a drawer's travel is 0.8 of
    its box depth, at most about 0.38 m; fits seen short by up to 27 cm."""
    guarded_pull_speed: float = 0.05
    """Speed of the guarded pull's command along its line, m/s (ramped in over 0.2 s)."""
    guarded_pull_force: float = 15.0
    """The guarded pull stops advancing once the arm's lag behind its command along the line,
    times the arm's stiffness at the tool along it, reaches this, N; the arm is then commanded
    where it is. Above a moving drawer's resistance (3 N of runner friction, `JOINT_FRICTION`, and
    2 N s/m of damping), under the 80 N a contact grip's friction holds (2 x 40 N squeeze, mu 1)."""
    pull_on: bool = True
    """Where the arm's own reach ended the guarded pull (`planning.scene.reach_limit` at its last
    joint positions along its line: a joint at a limit that going on drives further, links
    touching that going on brings closer), the robot lets go, its base is placed
    again in front of the handle where the hand left it, and it grasps and pulls on to the stop,
    once (`systems.task.pull_on`; the base's drive is not simulated). A door's turn that ended
    `systems.task.TURN_ON_MIN` or more short of its planned turn, as the hand measured it, is
    taken on likewise, the door as the hand felt it (`systems.task.turn_on`)."""

    second_turn: bool = True
    """A door's pull (a planned handle path that is no line, `straight_pull`): once it has
    settled, the robot compares the angle its tool swept about the circle through its own path
    (forward kinematics of its joint positions since the fingers closed) with the angle the plan's
    keypoints turn the handle by about their hinge to the target (`planned_door_turn`), and turns
    the door on (or back) by the difference about that circle (`door_turn`, `turn_step`), from
    where the hand is, when it exceeds `second_turn_min`,
    at most `second_turn_max`, over `second_pull_time`. With the object's pose a few degrees off,
    the planned arc is not the door's: the compliant arm follows the true hinge and stops short of
    or past the target (docs/SIMULATION.md, "Turning a door by what the hand swept"). A pull
    planned along a line (the keypoints say drawer) whose held hand swept an arc was a door's: the
    robot turns it on about that circle until the hand has swept `q_target` of the door's range
    (`feels_for_a_door`; docs/SIMULATION.md, "A door taken for a drawer")."""
    second_turn_min: float = float(np.radians(1.0))
    second_turn_max: float = float(np.radians(25.0))
    second_turn_max_hinge_gap: float | None = None
    """The door is turned only when the hinge its hand felt (the circle's axis) lies within this
    of the keypoints' hinge line (`hinge_gap`), m; inf: always; None: by the grasp
    (`turn_max_hinge_gap`). `SimulationResult.hinge_gap` records the gap either way."""
    regrasps: int = 2
    """How many times the robot tries again when its fingers close on nothing (a gripper senses
    it from their closed width; here the grip point outside `capture_half_extents` at the close):
    it opens them (`regrasp_open`), moves the tool along the approach (`regrasp_move`) and closes
    them again, first `regrasp_step` further than the planned grasp, then as far short of it, then
    twice as far each way (`try_steps`); the rest of the plan follows shifted by that joint step.
    0: one close only. The handle of a fit in a room lay 1.6-3.2 cm off, mostly beyond the
    predicted point along the approach; furniture fits also leave it short of the point, the hand
    then stopped beyond the bar (docs/SIMULATION.md, "Trying again after a miss")."""
    regrasp_step: float = 0.02
    """How far along the approach each new try moves, m: the fingers' pads catch a bar within
    about 2 cm either side of the tool point along the approach."""
    regrasp_open: float = 0.3
    """Time the fingers take to open after a miss, s."""
    regrasp_move: float = 0.5
    """Time the tool takes to move to the next try, s."""

    def __post_init__(self) -> None:
        if not 0.0 < self.grasped_stiffness <= 1.0:
            raise NfrDrakeError("simulation: grasped_stiffness must lie in (0, 1]")
        if self.grasp not in GRASPS:
            raise NfrDrakeError(f"simulation: grasp must be one of {', '.join(GRASPS)}, got {self.grasp!r}")
        if self.squeeze_force <= 0.0:
            raise NfrDrakeError("simulation: squeeze_force must be positive")
        if not 0.0 <= self.second_pull_min <= self.second_pull_max or self.second_pull_time <= 0.0:
            raise NfrDrakeError("simulation: need 0 <= second_pull_min <= second_pull_max and "
                                "second_pull_time > 0")
        if self.pull_to_stop < 0.0 or not 0.0 < self.pull_to_stop_stiffness <= 1.0:
            raise NfrDrakeError("simulation: need pull_to_stop >= 0 and pull_to_stop_stiffness in (0, 1]")
        if self.guarded_pull < 0.0 or self.guarded_pull_speed <= 0.0 or self.guarded_pull_force <= 0.0:
            raise NfrDrakeError("simulation: need guarded_pull >= 0, guarded_pull_speed > 0 and "
                                "guarded_pull_force > 0")
        if self.regrasps < 0 or self.regrasp_step <= 0.0 or min(self.regrasp_open, self.regrasp_move) <= 0.0:
            raise NfrDrakeError("simulation: need regrasps >= 0, and regrasp_step, regrasp_open and "
                                "regrasp_move > 0")

    @property
    def contact(self) -> bool:
        return self.grasp == "contact"

    @property
    def turn_max_hinge_gap(self) -> float:
        """`second_turn_max_hinge_gap`, m, or where it is None the grasp's own:
        `CONTACT_TURN_MAX_HINGE_GAP` for the contact grasp (the stiff arm keeps the hand on the
        plan's arc, so a felt circle far from the keypoints' hinge says the bar slid along the
        fingers and its sweep is no measure of the door's), inf for the constraint grasp (the
        compliant arm follows the true hinge: the turn corrects the keypoints' hinge)."""
        if self.second_turn_max_hinge_gap is not None:
            return self.second_turn_max_hinge_gap
        return CONTACT_TURN_MAX_HINGE_GAP if self.contact else float("inf")

    def pulls_again(self, plan: PlanResult) -> bool:
        """Whether the run takes `second_pull_time` after the opening to pull again: a contact
        grasp whose planned handle path is straight (`straight_pull`)."""
        return self.contact and self.second_pull and straight_pull(plan) is not None

    def turns_again(self, plan: PlanResult, keypoints: KeypointTrajectory | None) -> bool:
        """Whether the run takes `second_pull_time` after the opening to turn the door on by what
        its hand swept short (`second_turn`): a plan whose handle path is no line, made from
        `keypoints` with a hinge."""
        return (self.second_turn and keypoints is not None and "hinge_top" in keypoints.names
                and straight_pull(plan) is None)

    def feels_for_a_door(self, plan: PlanResult) -> bool:
        """Whether the run takes `second_pull_time` after a pull planned along a line (the
        keypoints say drawer; not one that `pulls_to_stop`) to turn the part on as a door where the
        held hand swept an arc (`second_turn`, `felt_door_turn_offset`): to `q_target` of the
        door's range (a generated door's quarter turn, `DOOR_OPENING`)."""
        return self.second_turn and straight_pull(plan) is not None and not self.pulls_to_stop(plan)

    def pulls_to_stop(self, plan: PlanResult) -> bool:
        """Whether the run ends with a guarded pull to the stop (`PullToStop`): a constraint grasp
        whose plan pulls along a line (`straight_pull` within `_STOP_LINE`) to the end of travel
        (last waypoint q >= 1)."""
        return (not self.contact and self.guarded_pull > 0.0 and plan.waypoints[-1].q >= 1.0
                and straight_pull(plan, _STOP_LINE) is not None)

    @property
    def regrasp_time(self) -> float:
        """The time a missed close adds to the run, s: the close itself (`dwell`), the fingers
        opening and the tool moving deeper."""
        return self.dwell + self.regrasp_open + self.regrasp_move

    def guarded_pull_time(self) -> float:
        """The longest the guarded pull takes, s: its distance at its speed, the ramp, a settle."""
        return self.guarded_pull / self.guarded_pull_speed + _GUARD_RAMP + self.settle

    def finger_target(self, closed: float) -> float:
        """Each finger's commanded opening when closing on something `closed` m from the centre
        (the constraint grasp), m: past the pads by `squeeze_force / Kp` for a contact grasp."""
        return -self.squeeze_force / _KP[NUM_ARM_JOINTS] if self.contact else closed


@dataclass
class SimulationResult:
    """What the simulated arm did to the true object.

    Attributes:
        success: grasped, final articulation within tolerance, and drift within tolerance.
        grasped: whether the grasp constraints were switched on.
        joint_type: "revolute" (errors in rad) or "prismatic" (m).
        q_target, q_final: articulations in [0, 1].
        joint_error: |final - target| joint value, rad or m.
        grasp_offset: distance from the tool origin to the grip point when the fingers closed, m
            (inside the capture region when grasped; the closing fingers take it up).
        max_drift: largest move of the held grip point in the tool frame from the end of the
            grasp (fingers closed) on: the hand slipping on or dragging the handle, m (the hold's own
            offset, e.g. a bar held `PlannerConfig.grasp_depth` deep, is not drift). When not
            grasped, the distance from the tool origin to the grip point at the end.
        max_constraint_force: largest force the hand (and any contact) exerts on the moving part
            from the end of the grasp on (the end stop's impact included), from its bodies'
            momentum balance, N.
        times: sample times, s, shape (M,); q_object: articulation, (M,); p_W_tool, p_W_handle: (M, 3),
            p_W_handle being the grip point (nearest the tool until the grasp, then the held one).
    """

    success: bool
    grasped: bool
    joint_type: str
    q_target: float
    q_final: float
    joint_error: float
    grasp_offset: float
    max_drift: float
    max_constraint_force: float
    times: np.ndarray = field(repr=False)
    q_object: np.ndarray = field(repr=False)
    p_W_tool: np.ndarray = field(repr=False)
    p_W_handle: np.ndarray = field(repr=False)
    grasp: str = "constraint"
    shortfall: float = float("nan")
    """The pull's shortfall the robot measured before pulling again (`SecondPull`), m; nan when
    it did not measure (no straight pull by contact, or no grasp)."""
    pulled_past: float = float("nan")
    """How far the guarded pull to the stop (`PullToStop`) commanded the tool past the plan's end
    before the force it sensed stopped it, m; nan without one."""
    tries: int = 1
    """How many times the fingers closed (1: the first close held the handle or no try was
    left, `SimulationConfig.regrasps`); `grasp_offset` is the last close's."""
    turned: float = float("nan")
    """The angle the robot turned a door on after its planned pull, by what its hand swept short
    of the keypoints' turn about their hinge, or of the target's on a straight pull whose hand
    swept an arc (`SimulationConfig.second_turn`), rad (negative: back); 0 when within
    `second_turn_min` or a straight pull's hand swept no arc; nan when it did not measure (no
    grasp, or a pull it does not check)."""
    q_pulled: float = float("nan")
    """The articulation (in [0, 1]) once the planned motion had settled, before any second pull,
    turn or guarded pull."""
    hinge_gap: float = float("nan")
    """Where the robot measured a door's turn: the horizontal distance from the hinge its hand
    felt to the keypoints' hinge line, m (`corrections.hinge_gap`); nan otherwise."""
    q_robot: np.ndarray = field(default_factory=lambda: np.full(9, np.nan), repr=False)
    """The robot's positions at the end (arm joints, then fingers; rad, m), (9,)."""
    pull_line: np.ndarray = field(default_factory=lambda: np.full(3, np.nan), repr=False)
    """The unit direction (W, (3,)) the guarded pull to the stop went along (`felt_line`); nan
    without one."""
    felt_from: float = float("nan")
    """The time the pull began, the fingers closed on the handle, s: the tool's path from then on
    (`p_W_tool`) is the held hand's, what the robot felt; nan without a grasp."""

    def summary(self) -> str:
        """One line: SUCCESS or FAILURE, then `details`."""
        return f"{'SUCCESS' if self.success else 'FAILURE'}: {self.details()}"

    def details(self) -> str:
        """The outcome's figures in one line, without the verdict."""
        return (f"articulation {self.q_final:.3f} (target {self.q_target:.3f}, error "
                f"{joint_error_text(self.joint_type, self.joint_error)}), grasped {self.grasped} (offset "
                f"{self.grasp_offset * 100:.1f} cm), hand-to-handle drift "
                f"{self.max_drift * 100:.1f} cm, largest constraint force {self.max_constraint_force:.1f} N, "
                f"{self.grasp} grasp, {self.tries} {'close' if self.tries == 1 else 'closes'}")


def joint_error_text(joint_type: str, error: float) -> str:
    """An error of the articulated joint in its unit: `error` in rad ("1.2 deg") for a revolute
    joint, in m ("1.2 cm") for a prismatic one."""
    return f"{np.degrees(error):.1f} deg" if joint_type == "revolute" else f"{error * 100:.1f} cm"


def couple_fingers(plant: MultibodyPlant, robot) -> None:
    """Move the hand's two fingers together (a SAP coupler constraint, as the Panda hand's one
    motor and rack do), so a squeezed handle or item stays centred between them: with each finger
    on its own PD they slid across together (about 6 N per cm, from the gains' imbalance) until
    one reached its stop and a knob slipped out. Before `plant.Finalize()`; discrete SAP plants."""
    plant.AddCouplerConstraint(plant.GetJointByName(FINGER_JOINTS[0], robot),
                               plant.GetJointByName(FINGER_JOINTS[1], robot), 1.0, 0.0)


class JointFriction(LeafSystem):
    """Coulomb friction on one joint of a plant, regularised: -F tanh(v / v_s), as the plant's
    applied generalized force (discrete plants apply it explicitly over a step, so v_s is the
    smallest speed that keeps it stable: F dt / v_s at most half the joint's mass or inertia).

    Input port "state": the plant's [q; v]. Output port "generalized_force": (num_velocities,),
    nonzero at the joint's velocity only (N or N m)."""

    def __init__(self, plant: MultibodyPlant, joint, friction: float):
        super().__init__()
        context = plant.CreateDefaultContext()
        self._nq, self._nv = plant.num_positions(), plant.num_velocities()
        self._index = joint.velocity_start()
        mass = plant.CalcMassMatrix(context)[self._index, self._index]
        self._friction = friction
        self._v_s = friction * plant.time_step() / (0.5 * mass)
        self.DeclareVectorInputPort("state", self._nq + self._nv)
        self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc)

    def _calc(self, context, output: BasicVector) -> None:
        v = self.get_input_port(0).Eval(context)[self._nq + self._index]
        tau = np.zeros(self._nv)
        tau[self._index] = -self._friction * np.tanh(v / self._v_s)
        output.SetFromVector(tau)


def add_joint_friction(builder: DiagramBuilder, plant: MultibodyPlant, joint) -> JointFriction:
    """Coulomb friction `JOINT_FRICTION` on the articulated `joint` (after Finalize; the plant's
    applied generalized force input is then taken)."""
    friction = builder.AddNamedSystem("joint_friction", JointFriction(
        plant, joint, JOINT_FRICTION[joint.type_name()]))
    builder.Connect(plant.get_state_output_port(), friction.get_input_port())
    builder.Connect(friction.get_output_port(), plant.get_applied_generalized_force_input_port())
    return friction


def set_arm_gains(plant: MultibodyPlant, robot) -> None:
    """Give the robot's actuators (arm joints 1-7, then the fingers) the implicit PD gains _KP, _KD.
    Before `plant.Finalize()`."""
    actuators = [plant.get_joint_actuator(JointActuatorIndex(i)) for i in range(plant.num_actuators())]
    robot_actuators = [a for a in actuators if a.model_instance() == robot]
    for actuator, kp, kd in zip(robot_actuators, _KP, _KD, strict=True):
        actuator.set_controller_gains(PdControllerGains(p=kp, d=kd))


def add_gravity_compensation(builder: DiagramBuilder, plant: MultibodyPlant, robot, X_WB) -> MultibodyPlant:
    """Feed the robot's actuation with gravity compensation of a Panda alone at X_WB (feed-forward to
    the implicit PD of its actuators). Returns the controller's plant: the InverseDynamics system
    only refers to it, so the caller must hold it for as long as the diagram runs."""
    controller_plant = MultibodyPlant(0.0)
    add_panda(controller_plant, X_WB)
    controller_plant.Finalize()
    gravity = builder.AddNamedSystem("gravity_compensation", InverseDynamics(
        controller_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
    builder.Connect(plant.get_state_output_port(robot), gravity.get_input_port_estimated_state())
    builder.Connect(gravity.get_output_port(), plant.get_actuation_input_port(robot))
    return controller_plant


class CompliantCommand(LeafSystem):
    """Scales the arm's implicit PD gains from time `t_soft` on, by rewriting its desired state.

    The plant's PD actuators apply tau = Kp (q_d - q) + Kd (v_d - v). Commanding
    q_c = q + a (q_d - q) and v_c = v + a (v_d - v), with the measured state (q, v), gives
    a Kp (q_d - q) + a Kd (v_d - v) towards the plan; the measured part is taken at the start of the
    step, so the implicit solve adds only damping, kept stable at any a in (0, 1].

    Input ports: "desired_state" [q_d; v_d] and "measured_state" [q; v] of the robot, each
    2 * num_positions values (arm joints first, then fingers). Output port "command": [q_c; v_c].
    Only the first `num_scaled` joints (the arm) are scaled; the fingers keep their gains.
    `t_soft` lives in the context (a numeric parameter, `soften_from`): a missed grasp delays it.
    """

    def __init__(self, num_positions: int, num_scaled: int, t_soft: float, stiffness: float):
        super().__init__()
        self._n = num_positions
        self._scale = np.ones(num_positions)
        self._scale[:num_scaled] = stiffness
        self.DeclareNumericParameter(BasicVector([t_soft]))
        self.DeclareVectorInputPort("desired_state", 2 * num_positions)
        self.DeclareVectorInputPort("measured_state", 2 * num_positions)
        self.DeclareVectorOutputPort("command", 2 * num_positions, self._calc_command)

    def soften_from(self, root_context, t_soft: float) -> None:
        """Scale the gains from time `t_soft` (s) on, in the diagram's context `root_context`."""
        self.GetMyMutableContextFromRoot(root_context).get_mutable_numeric_parameter(0).SetAtIndex(0, t_soft)

    def _calc_command(self, context, output: BasicVector) -> None:
        desired = self.get_input_port(0).Eval(context)
        if context.get_time() < context.get_numeric_parameter(0).GetAtIndex(0):
            output.SetFromVector(desired)
            return
        measured = self.get_input_port(1).Eval(context)
        a = np.r_[self._scale, self._scale]
        output.SetFromVector(measured + a * (desired - measured))


_STRAIGHT = (0.003, 0.03)
"""A planned handle path within the larger of these of its chord (m, and a fraction of its
length) is a straight pull: a drawer's path from the neural field's keypoints bows 3-5 mm over
27-34 cm (1-2%), a door's arc opened 14 degrees or more over 3%."""


_STOP_LINE = (0.003, 0.1)
"""As `_STRAIGHT`, for a pull to the stop (`PullToStop`), which needs only the line's direction: a
drawer's fitted path in a room bowed 5.6 mm over 18 cm (3.1%); a door's arc opened 45 degrees or
more bows 10% (tan(angle / 4) / 2 of its chord) or more."""


def straight_pull(plan: PlanResult, tolerance: tuple[float, float] = _STRAIGHT) -> np.ndarray | None:
    """The planned handle travel (last waypoint minus first, W, m, (3,)) when the handle's
    waypoints lie within `tolerance` (`_STRAIGHT` by default) of that line and it is over 1 cm
    long (a drawer's pull), else None (a door's arc)."""
    points = np.array([w.p_WH for w in plan.waypoints])
    travel = points[-1] - points[0]
    length = np.linalg.norm(travel)
    if length < 0.01:
        return None
    off = (points - points[0]) - np.outer((points - points[0]) @ travel / length**2, travel)
    return travel if np.linalg.norm(off, axis=1).max() <= max(tolerance[0], tolerance[1] * length) else None


def guarded_pull_direction(plan: PlanResult) -> np.ndarray:
    """The unit direction (W, (3,)) along which a guarded pull to the stop goes on: the planned
    handle travel's (`straight_pull` within `_STOP_LINE`; a plan that `pulls_to_stop`)."""
    line = straight_pull(plan, _STOP_LINE)
    return line / np.linalg.norm(line)


class SecondPull(LeafSystem):
    """Adds a joint offset to the robot's desired state: none until one is set (`set`), then
    dq (arm joints, rad) ramped in smoothly over [t_in, t_in + ramp] and, when t_out >= 0, out
    over [t_out, t_out + ramp_out]; the velocities get the ramp's rate. From t_in to t_soft the
    arm's gains are scaled by `stiffness` (as `CompliantCommand` does, from the measured state).

    Input ports "desired_state" and "measured_state", output port "command": [q; v], 2 *
    num_positions values (arm joints first). The offset lives in the context (a numeric
    parameter), set during a run (`pull`, `hold`)."""

    def __init__(self, num_positions: int):
        super().__init__()
        self._n = num_positions
        self.DeclareNumericParameter(BasicVector(np.r_[np.zeros(NUM_ARM_JOINTS), 0.0, 1.0, -1.0, 1.0,
                                                       0.0, 1.0]))
        self.DeclareVectorInputPort("desired_state", 2 * num_positions)
        self.DeclareVectorInputPort("measured_state", 2 * num_positions)
        self.DeclareVectorOutputPort("command", 2 * num_positions, self._calc)

    def set(self, root_context, dq: np.ndarray, t_in: float, ramp: float, t_out: float = -1.0,
            ramp_out: float = 1.0, t_soft: float = 0.0, stiffness: float = 1.0) -> None:
        """Set the offset dq (NUM_ARM_JOINTS,) in the diagram's context `root_context`."""
        context = self.GetMyMutableContextFromRoot(root_context)
        context.get_mutable_numeric_parameter(0).SetFromVector(
            np.r_[dq, t_in, ramp, t_out, ramp_out, t_soft, stiffness])

    def pull(self, root_context, robot_plant: MultibodyPlant, plan: PlanResult, q_grasp: np.ndarray,
             q_now: np.ndarray, config: SimulationConfig, t: float, t_out: float = -1.0,
             ramp_out: float = 1.0) -> float:
        """At time t, the planned pull settled, the robot at `q_now` (measured, (9,)): pull again by
        the measured shortfall (`second_pull_offset`; past the planned end and compliant when the
        plan pulls to the end of travel, `pull_to_stop`), ramped in over 40% of
        `second_pull_time`, out from t_out if >= 0. Returns the shortfall, m."""
        to_stop = plan.waypoints[-1].q >= 1.0
        q_command = plan.trajectory.value(plan.trajectory.end_time()).ravel()
        dq, shortfall = second_pull_offset(robot_plant, straight_pull(plan), q_grasp, q_now, q_command,
                                           config, config.pull_to_stop if to_stop else 0.0)
        t_soft = t + 0.8 * config.second_pull_time if to_stop else t
        self.set(root_context, dq, t, 0.4 * config.second_pull_time, t_out, ramp_out, t_soft,
                 config.pull_to_stop_stiffness)
        return shortfall

    def hold(self, root_context, q_now: np.ndarray, q_command: np.ndarray) -> None:
        """From now on, full stiffness and the arm held where it is (`q_now`, measured): the
        offset becomes q_now - q_command (the plan's end), its ramp-out kept."""
        context = self.GetMyMutableContextFromRoot(root_context)
        p = context.get_numeric_parameter(0).get_value().copy()
        p[:NUM_ARM_JOINTS] = (q_now - q_command)[:NUM_ARM_JOINTS]
        p[NUM_ARM_JOINTS:NUM_ARM_JOINTS + 2] = (context.get_time() - 1.0, 1e-3)  # fully in
        p[NUM_ARM_JOINTS + 4] = context.get_time()  # the compliant stretch ends
        context.get_mutable_numeric_parameter(0).SetFromVector(p)

    @staticmethod
    def _ramp(t: float, t0: float, duration: float) -> tuple[float, float]:
        x = np.clip((t - t0) / duration, 0.0, 1.0)
        rate = 0.5 * np.pi / duration * np.sin(np.pi * x) if 0.0 < x < 1.0 else 0.0
        return 0.5 - 0.5 * np.cos(np.pi * x), rate

    def _calc(self, context, output: BasicVector) -> None:
        desired = self.get_input_port(0).Eval(context).copy()
        p = context.get_numeric_parameter(0).get_value()
        dq, (t_in, ramp, t_out, ramp_out, t_soft, stiffness) = p[:NUM_ARM_JOINTS], p[NUM_ARM_JOINTS:]
        t = context.get_time()
        if np.any(dq):
            a, a_dot = self._ramp(t, t_in, ramp)
            if t_out >= 0.0:
                b, b_dot = self._ramp(t, t_out, ramp_out)
                a, a_dot = a * (1.0 - b), a_dot * (1.0 - b) - a * b_dot
            desired[:NUM_ARM_JOINTS] += a * dq
            desired[self._n:self._n + NUM_ARM_JOINTS] += a_dot * dq
        if t_in <= t < t_soft and stiffness < 1.0:
            measured = self.get_input_port(1).Eval(context)
            arm = np.r_[np.arange(NUM_ARM_JOINTS), self._n + np.arange(NUM_ARM_JOINTS)]
            desired[arm] = measured[arm] + stiffness * (desired[arm] - measured[arm])
        output.SetFromVector(desired)


def second_pull_offset(robot_plant: MultibodyPlant, travel: np.ndarray, q_grasp: np.ndarray,
                       q_end: np.ndarray, q_command: np.ndarray, config: SimulationConfig,
                       past: float = 0.0) -> tuple[np.ndarray, float]:
    """The arm joints' offset (NUM_ARM_JOINTS,) that moves the tool by the pull's shortfall along
    the planned handle `travel` (W, m), and the shortfall (m): the planned length less the tool's
    travel from `q_grasp` (the fingers just closed) to `q_end` (the pull settled), both measured
    joint positions of the robot (9,), by forward kinematics in `robot_plant` (the arm alone, as
    the controller's). The offset is the least-squares joint step at `q_command` (the commanded
    end) for that translation, the hand's orientation kept; zero below `second_pull_min`, the
    shortfall clipped to `second_pull_max`; `past` (m) is added (a pull to the stop: always
    moves)."""
    context = robot_plant.CreateDefaultContext()
    tool = robot_plant.GetFrameByName(TOOL_FRAME)
    length = float(np.linalg.norm(travel))
    u = travel / length
    tool_at = []
    for q in (q_grasp, q_end):
        robot_plant.SetPositions(context, q)
        tool_at.append(tool.CalcPoseInWorld(context).translation())
    shortfall = length - float((tool_at[1] - tool_at[0]) @ u)
    step = (min(shortfall, config.second_pull_max) if shortfall >= config.second_pull_min else 0.0) + past
    if step <= 0.0:
        return np.zeros(NUM_ARM_JOINTS), shortfall
    return tool_step(robot_plant, q_command, step * u), shortfall


_GUARD_RAMP = 0.2
"""Time over which the guarded pull's speed ramps in, s."""


class PullToStop(LeafSystem):
    """A guarded pull, as a robot with joint position sensing makes one: from `start` on, the arm's
    command starts where the arm is (measured: the lag the pull before it left, which a drawer's
    slide held off the plan's line, does not count) and moves the tool on along a line at a set
    speed (ramped in over `_GUARD_RAMP`), the
    hand's orientation kept (differential inverse kinematics at the command, every `period`),
    until the force the arm's lag behind the command implies along the line reaches a set force,
    or the command has gone a set distance; the arm is then commanded where it is (measured) and
    stays there. The force is the lag of the tool (commanded less measured position by forward
    kinematics, W) through the arm's translational stiffness at the tool, (J K^-1 J^T)^-1 with J
    the tool's translational Jacobian at the measured joints and K the scaled PD gains (the hand
    free to turn on the handle), taken along the line; the lag includes the PD's damping term,
    J K_p^-1 K_d (v_command - v), the commanded rate pushing on a tool held still. On a drawer
    held at its stop the position term matched the force on the drawer within 10% (a lag along
    the line alone, times 1 / (u^T J K^-1 J^T u), read 5 times low: the drawer's runners hold the
    hand sideways), and without the damping term the pull stopped at 31 N of a set 15 N. A
    drawer's stop (or the arm's reach) ends the pull, not a predicted travel, and the pull on the
    grip stays about that force.

    Input ports "desired_state" and "measured_state", output port "command": [q; v], 2 *
    num_positions values (arm joints first; the fingers pass through). The settings live in the
    context (a numeric parameter, `start`), the command's offset from the desired state in its
    discrete state: [dq (NUM_ARM_JOINTS), its rate, 1 once started (else 0), distance gone (m),
    time it stopped (s, -1 while going)]."""

    def __init__(self, robot_plant: MultibodyPlant, stiffness: float, period: float = 0.01):
        """`robot_plant`: the arm alone (as the controller's; the caller keeps it alive), whose
        positions are the robot's; `stiffness`: the fraction of the PD gains the arm has during
        the pull."""
        super().__init__()
        self._plant, self._context = robot_plant, robot_plant.CreateDefaultContext()
        self._n, self._period = robot_plant.num_positions(), period
        self._compliance = 1.0 / (stiffness * _KP[:NUM_ARM_JOINTS])  # rad / N m, per joint
        # [u (3), t_start, distance, speed, force, active]
        self.DeclareNumericParameter(BasicVector(np.r_[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0]))
        self._state = self.DeclareDiscreteState(np.r_[np.zeros(2 * NUM_ARM_JOINTS + 2), -1.0])
        self.DeclareVectorInputPort("desired_state", 2 * self._n)
        self.DeclareVectorInputPort("measured_state", 2 * self._n)
        self.DeclareVectorOutputPort("command", 2 * self._n, self._calc)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)

    def start(self, root_context, u: np.ndarray, t: float, distance: float, speed: float,
              force: float) -> None:
        """Pull along unit `u` (W, (3,)) from time t, by at most `distance` (m) at `speed` (m/s),
        until the force the lag implies reaches `force` (N)."""
        context = self.GetMyMutableContextFromRoot(root_context)
        context.get_mutable_numeric_parameter(0).SetFromVector(np.r_[u, t, distance, speed, force, 1.0])

    def stopped_at(self, root_context) -> tuple[float, float]:
        """The time the pull stopped (s; nan while it goes on or never started) and the distance
        its command went along the line (m)."""
        x = self.GetMyContextFromRoot(root_context).get_discrete_state(self._state).get_value()
        return (float(x[-1]) if x[-1] >= 0.0 else float("nan")), float(x[-2])

    def _tool_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool's position in W (3,) and spatial velocity Jacobian (6, NUM_ARM_JOINTS) at q."""
        X_WT, J = tool_pose_and_jacobian(self._plant, self._context, q)
        return X_WT.translation(), J

    def _update(self, context, state) -> None:
        settings = context.get_numeric_parameter(0).get_value()
        u, (t_start, distance, speed, force, active) = settings[:3], settings[3:]
        x = context.get_discrete_state(self._state).get_value().copy()
        t = context.get_time()
        if not active or t < t_start or x[-1] >= 0.0:
            return
        n = NUM_ARM_JOINTS
        desired, measured = self.get_input_port(0).Eval(context), self.get_input_port(1).Eval(context)
        q_desired, q_measured = desired[:self._n], measured[:self._n]
        if not x[-3]:  # the command starts where the arm is
            x[:n], x[-3] = (q_measured - q_desired)[:n], 1.0
        q_command = q_desired + np.r_[x[:n], np.zeros(self._n - n)]
        p_command, J_command = self._tool_jacobian(q_command)
        p_measured, J_measured = self._tool_jacobian(q_measured)
        J = J_measured[3:]
        v_lag = desired[self._n:self._n + n] + x[n:2 * n] - measured[self._n:self._n + n]
        compliance = (J * self._compliance) @ J.T  # m / N, the hand free to turn
        lag = p_command - p_measured + J @ (_KD[:n] / _KP[:n] * v_lag)  # the PD's damping term too
        pulling = float(np.linalg.solve(compliance, lag) @ u)
        if pulling >= force or x[-2] >= distance:  # the stop (or the reach): hold where it is
            x[:n], x[n:2 * n], x[-1] = (q_measured - q_desired)[:n], 0.0, t
        else:
            rate = speed * min(1.0, (t - t_start) / _GUARD_RAMP)
            x[n:2 * n] = np.linalg.lstsq(J_command, np.r_[np.zeros(3), rate * u], rcond=None)[0]
            x[:n] += self._period * x[n:2 * n]
            x[-2] += self._period * rate
        state.get_mutable_vector(self._state).SetFromVector(x)

    def _calc(self, context, output: BasicVector) -> None:
        command = self.get_input_port(0).Eval(context).copy()
        x = context.get_discrete_state(self._state).get_value()
        n = NUM_ARM_JOINTS
        command[:n] += x[:n]
        command[self._n:self._n + n] += x[n:2 * n]
        output.SetFromVector(command)


def try_steps(tries: int) -> int:
    """How many `regrasp_step`s along the approach the `tries`-th close after the first lies from
    the planned grasp: 0, then 1 further, 1 back, 2 further, 2 back, ..."""
    return (tries + 1) // 2 * (1 if tries % 2 else -1)


def _desired_state_trajectory(plan: PlanResult, config: SimulationConfig, hold: float = 0.0,
                              misses: int = 0, dq_miss: np.ndarray | None = None) -> PiecewisePolynomial:
    """The plan with a dwell at the grasp and the fingers closing during it, held `hold` s longer
    at its end; [q; v], 9 + 9 values. With `misses` > 0 the grasp is first missed that many times:
    each time the fingers close (`dwell`), open (`regrasp_open`) and the arm moves over
    `regrasp_move` to the next try, `try_steps` joint steps `dq_miss` (NUM_ARM_JOINTS,;
    `regrasp_step`) from the planned grasp; the rest of the plan follows `misses *
    config.regrasp_time` s later, shifted by the last try's steps."""
    traj, t_g, dwell = plan.trajectory, plan.t_grasp, config.dwell
    period, opened = config.regrasp_time, config.dwell + config.regrasp_open
    velocity = traj.MakeDerivative()
    t_last = t_g + misses * period  # the close that holds (or the last try)
    end = plan.duration + dwell + config.settle + hold + misses * period
    missed = [t_g + j * period + d for j in range(misses) for d in (0.0, dwell, opened)]
    times = np.unique(np.r_[np.arange(0.0, end, 0.01), missed, t_last, t_last + dwell, end])
    dq = np.zeros(NUM_ARM_JOINTS) if dq_miss is None else dq_miss

    def plan_time(t):
        return t if t <= t_g else max(t_g, t - dwell) if t < t_g + dwell else min(t - dwell, plan.duration)

    qs, vs = [], []
    for t in times:
        if t_g < t < t_last:  # a missed close, then the move to the next try
            j, s = divmod(t - t_g, period)
            a = np.clip((s - opened) / config.regrasp_move, 0.0, 1.0)
            a_dot = 0.5 * np.pi / config.regrasp_move * np.sin(np.pi * a) if 0.0 < a < 1.0 else 0.0
            q = traj.value(t_g).ravel().copy()
            v = np.zeros_like(q)
            here, on = try_steps(int(j)), try_steps(int(j) + 1)
            q[:NUM_ARM_JOINTS] += (here + (on - here) * (0.5 - 0.5 * np.cos(np.pi * a))) * dq
            v[:NUM_ARM_JOINTS] = (on - here) * a_dot * dq
            closing = min(s / dwell, 1.0) if s <= dwell else max(0.0, 1.0 - (s - dwell) / config.regrasp_open)
        else:
            shift = misses * period if t >= t_last else 0.0
            tp = plan_time(t - shift)
            q = traj.value(tp).ravel().copy()
            moving = (t <= t_g or t >= t_last + dwell) and tp < plan.duration
            v = velocity.value(tp).ravel().copy() if moving else np.zeros_like(q)
            q[:NUM_ARM_JOINTS] += (try_steps(misses) if t >= t_last else 0) * dq
            closing = np.clip((t - t_last) / dwell, 0.0, 1.0)
        q[NUM_ARM_JOINTS:] = FINGER_OPEN + closing * (config.finger_closed - FINGER_OPEN)
        v[NUM_ARM_JOINTS:] = 0.0
        qs.append(q)
        vs.append(v)
    qs, vs = np.array(qs).T, np.array(vs).T
    return PiecewisePolynomial.FirstOrderHold(times, np.vstack([qs, vs]))


class PlanTries(LeafSystem):
    """The robot's desired state [q; v] (output port "desired_state") from one of several timelines
    of the plan, the k-th with k missed closes first (`_desired_state_trajectory`); all agree up to
    the first close, the k-th and the (k+1)-th up to the (k+1)-th close. Which one lives in the
    context (a numeric parameter), switched during a run when the fingers miss (`select`)."""

    def __init__(self, timelines: list[PiecewisePolynomial]):
        super().__init__()
        self._timelines = timelines
        self.DeclareNumericParameter(BasicVector([0.0]))
        self.DeclareVectorOutputPort("desired_state", timelines[0].rows(), self._calc)

    def select(self, root_context, misses: int) -> None:
        """Follow the timeline with `misses` missed closes from now on."""
        self.GetMyMutableContextFromRoot(root_context).get_mutable_numeric_parameter(0).SetAtIndex(0, misses)

    def _calc(self, context, output: BasicVector) -> None:
        timeline = self._timelines[int(context.get_numeric_parameter(0).GetAtIndex(0))]
        output.SetFromVector(timeline.value(context.get_time()).ravel())


def simulate_articulation(obj: SceneObject, plan: PlanResult, q_target: float,
                          meshcat: Meshcat | None = None, config: SimulationConfig | None = None,
                          keypoints: KeypointTrajectory | None = None) -> SimulationResult:
    """Run the plan on the true object and measure the outcome; records into `meshcat` if given.
    `keypoints`: those the plan was made from (a door's turn by what the hand swept compares with
    their hinge's turn, `SimulationConfig.second_turn`; None: no turn). Raises
    `StartsInsideObject` where the robot starts inside the object (`robot_inside`)."""
    config = config or SimulationConfig()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=config.time_step, discrete_contact_approximation="sap"), builder)
    robot = add_panda(plant, plan.X_WB)
    floor = add_floor(plant)
    add_pedestal(plant, plan.X_WB)
    model = obj.add_to(plant)
    set_arm_gains(plant, robot)
    couple_fingers(plant, robot)
    hand = plant.GetBodyByName("panda_hand", robot)
    handle_body = plant.GetBodyByName(obj.handle_body_name, model)
    if config.contact and not plant.GetCollisionGeometriesForBody(handle_body):
        raise NfrDrakeError(f"the handle body {obj.handle_body_name!r} has no collision geometry: fingers "
                            "closing on it by contact pass through it; give it a <collision> element, or "
                            "use the constraint grasp (--grasp constraint)")
    X_HT = plant.GetFrameByName(TOOL_FRAME, robot).GetFixedPoseInBodyFrame()
    bar_B = obj.bar_B / np.linalg.norm(obj.bar_B)
    grips_B = grip_points(obj.p_BH, bar_B, obj.grip_half_length, config.grip_spacing)
    span_points = (1.0, -1.0) if config.grasp_half_span > 0.0 else (0.0,)
    constraint_ids = [  # constraint_ids[k]: the constraints of grip point k (none: a contact grasp)
        [plant.AddBallConstraint(hand, X_HT @ np.array([sign * config.grasp_half_span, 0.0, 0.0]),
                                 handle_body, p_BG + sign * config.grasp_half_span * bar_B)
         for sign in span_points if not config.contact]
        for p_BG in grips_B]
    if config.contact:
        hydroelastic_grip(plant, scene_graph, [plant.GetBodyByName(name, robot) for name in HAND_BODIES[1:]],
                          [plant.get_body(b) for b in plant.GetBodyIndices(model)])
    plant.Finalize()

    # A constraint grasp: the gripper does not touch the object's moving bodies.
    hand_bodies = [plant.GetBodyByName(name, robot) for name in HAND_BODIES]
    hand_geometries = GeometrySet([g for body in hand_bodies
                                   for g in plant.GetCollisionGeometriesForBody(body)])
    joint = plant.GetJointByName(obj.joint_name, model)
    moving_bodies = [plant.get_body(b) for b in plant.GetBodiesKinematicallyAffectedBy([joint.index()])]
    moving_geometries = GeometrySet([g for body in moving_bodies
                                     for g in plant.GetCollisionGeometriesForBody(body)])
    if not config.contact:
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeBetween(hand_geometries, moving_geometries))
    # The joint alone decides where the moving part goes: a real door or drawer clears the floor and
    # its neighbours, while a model's may rest on the floor (bottom edge at z = 0, or a mesh a
    # millimetre into it) or swing a few mm into a neighbouring front (an idealised hinge axis).
    moving_indices = {body.index() for body in moving_bodies}
    clear_of = GeometrySet([g for b in (*plant.GetBodyIndices(floor), *plant.GetBodyIndices(model))
                            if b not in moving_indices
                            for g in plant.GetCollisionGeometriesForBody(plant.get_body(b))])
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeBetween(clear_of, moving_geometries))

    controller_plant = add_gravity_compensation(builder, plant, robot, plan.X_WB)  # kept alive here
    add_joint_friction(builder, plant, joint)
    fingers = replace(config, finger_closed=config.finger_target(config.finger_closed))
    turns = config.turns_again(plan, keypoints)
    feels = config.feels_for_a_door(plan)
    again = config.second_pull_time if config.pulls_again(plan) or turns or feels else 0.0
    to_stop = config.guarded_pull_time() if config.pulls_to_stop(plan) else 0.0
    dq_miss = regrasp_step(controller_plant, plan.trajectory.value(plan.t_grasp).ravel(), config.regrasp_step)
    desired = builder.AddNamedSystem("plan", PlanTries(
        [_desired_state_trajectory(plan, fingers, again + to_stop, misses, dq_miss)
         for misses in range(config.regrasps + 1)]))
    second_pull = builder.AddNamedSystem("second_pull", SecondPull(plant.num_positions(robot)))
    builder.Connect(desired.get_output_port(), second_pull.get_input_port(0))
    builder.Connect(plant.get_state_output_port(robot), second_pull.get_input_port(1))
    t_activate = plan.t_grasp + 0.5 * config.dwell
    stiffness = 1.0 if config.contact else config.grasped_stiffness
    pull_to_stop = builder.AddNamedSystem("pull_to_stop", PullToStop(controller_plant, stiffness))
    builder.Connect(second_pull.get_output_port(), pull_to_stop.get_input_port(0))
    builder.Connect(plant.get_state_output_port(robot), pull_to_stop.get_input_port(1))
    command = builder.AddNamedSystem("compliance", CompliantCommand(
        plant.num_positions(robot), NUM_ARM_JOINTS, t_activate, stiffness))
    builder.Connect(pull_to_stop.get_output_port(), command.get_input_port(0))
    builder.Connect(plant.get_state_output_port(robot), command.get_input_port(1))
    builder.Connect(command.get_output_port(), plant.get_desired_state_input_port(robot))
    shut, opened = obj.shut_and_open(joint)
    AddKeypointTrajectorySource(builder, plant, joint, obj.ground_truth, (shut, opened))
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()

    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    span = opened - shut
    # A door's angle at q_target: of its joint's range (a generated door's quarter turn, a model
    # file's own, as `SceneObject.in_joint_units` tells its keypoints); a slide sweeps no arc.
    door_target = q_target * (abs(span) if joint.type_name() == "revolute" else DOOR_OPENING)
    set_joint_value(plant, plant_context, joint, shut + obj.ground_truth.q_current * span)
    lock_shut(plant, plant_context, [plant.GetJointByName(name, model) for name in obj.locked_joints])
    plant.SetPositions(plant_context, robot, plan.trajectory.value(0.0).ravel())
    inside = robot_inside(plant, scene_graph, context, robot, model)
    if inside is not None:
        raise StartsInsideObject(inside)
    for ids in constraint_ids:
        for cid in ids:
            plant.SetConstraintActiveStatus(plant_context, cid, False)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=32.0, set_visualizations_while_recording=False)
    simulator.Initialize()

    tool = plant.GetFrameByName(TOOL_FRAME, robot)

    def timeline(misses: int) -> tuple[float, ...]:
        """The run's times after `misses` missed closes, s: the fingers close (half-way through
        the dwell), the handle starts to move, the plan's pull has settled, the second pull
        holds; and the sample times from 0 to the end."""
        delay = misses * config.regrasp_time
        t_close, t_pull = plan.t_grasp + delay + 0.5 * config.dwell, plan.t_grasp + delay + config.dwell
        t_pulled = plan.duration + config.dwell + config.settle + delay
        end, t_held = t_pulled + again + to_stop, t_pulled + 0.8 * again
        samples = np.unique(np.r_[np.arange(0.0, end, config.sample_period), t_close, t_pull, t_pulled,
                                  t_held, end])
        return t_close, t_pull, t_pulled, t_held, list(samples)

    misses = 0
    t_activate, t_pull, t_pulled, t_held, samples = timeline(misses)
    grasped, grasp_offset, shortfall, holding = False, float("nan"), float("nan"), False
    turned = q_pulled = gap = float("nan")
    pull_line = np.full(3, np.nan)
    times, q_obj, p_tool, p_handle, p_held, forces = [], [], [], [], [], []
    while samples:
        t = samples.pop(0)
        simulator.AdvanceTo(t)
        if t == t_pull:
            q_grasp = plant.GetPositions(plant_context, robot)
        if t in (t_pulled, t_held):
            q_end = plan.trajectory.value(plan.trajectory.end_time()).ravel()
            q_end[:NUM_ARM_JOINTS] += try_steps(misses) * dq_miss  # the plan's last command
        if t == t_pulled:
            q_pulled = (joint.GetOnePosition(plant_context) - shut) / span
            # a hand that let go of the handle makes no correction (its fingers closed on nothing)
            holding = grasped and (not config.contact
                                   or fingers_hold(plant.GetPositions(plant_context, robot)))
        if t == t_pulled and again and holding:  # the robot measures its turn or its pull, goes on
            felt = np.array(p_tool)[np.array(times) >= t_pull]  # the tool's path by forward kinematics
            q_now = plant.GetPositions(plant_context, robot)
            dq = None
            if turns:  # a door's arc: turned on by what the hand swept short
                dq, turned, gap = door_turn_offset(controller_plant, felt, keypoints, q_target, q_now, q_end,
                                                   config.second_turn_min, config.second_turn_max,
                                                   config.turn_max_hinge_gap)
            elif feels:  # a straight pull: did the hand swing?
                dq, turned = felt_door_turn_offset(controller_plant, felt, door_target, q_now, q_end,
                                                   config.second_turn_min, config.second_turn_max)
            if dq is not None and turned:
                second_pull.set(context, dq, t, 0.4 * config.second_pull_time, t_soft=t)
            elif not turns and config.pulls_again(plan):  # pulled again by the shortfall
                shortfall = second_pull.pull(context, controller_plant, plan, q_grasp, q_now, config, t)
        if t == t_held and again and holding:
            second_pull.hold(context, plant.GetPositions(plant_context, robot), q_end)
        if t == t_pulled and to_stop and grasped:  # the guarded pull to the drawer's stop
            felt = np.array(p_tool)[np.array(times) >= t_pull]  # the tool's path by forward kinematics
            pull_line = felt_line(felt, guarded_pull_direction(plan))
            pull_to_stop.start(context, pull_line, t, config.guarded_pull,
                               config.guarded_pull_speed, config.guarded_pull_force)
        X_WT = tool.CalcPoseInWorld(plant_context)
        X_WHb = plant.EvalBodyPoseInWorld(plant_context, handle_body)
        if not grasped:  # until the grasp: the grip point nearest the tool
            grip = int(np.argmin(np.linalg.norm(grips_B - X_WHb.inverse() @ X_WT.translation(), axis=1)))
        p_WH = X_WHb @ grips_B[grip]
        if t == t_activate:  # the fingers close: they hold the handle or miss it
            grasp_offset = float(np.linalg.norm(X_WT.translation() - p_WH))
            if np.all(np.abs(X_WT.inverse() @ p_WH) <= config.capture_half_extents):
                for cid in constraint_ids[grip]:
                    plant.SetConstraintActiveStatus(plant_context, cid, True)
                grasped = True
            elif misses < config.regrasps:  # nothing between the fingers: open, move on, close again
                misses += 1
                t_activate, t_pull, t_pulled, t_held, samples = timeline(misses)
                samples = [s for s in samples if s > t]
                desired.select(context, misses)
                command.soften_from(context, t_activate)
        times.append(t)
        q_obj.append((joint.GetOnePosition(plant_context) - shut) / span)
        p_tool.append(X_WT.translation())
        p_handle.append(p_WH)
        p_held.append(X_WT.inverse() @ p_WH)
        if grasped and t >= t_pull:
            forces.append(_force_on_moving_part(plant, plant_context, moving_bodies, joint))
        if to_stop and pull_to_stop.stopped_at(context)[0] + config.settle <= t:
            break  # the guarded pull stopped and settled
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()

    p_tool, p_handle = np.array(p_tool), np.array(p_handle)
    times = np.array(times)
    max_drift = float(np.linalg.norm(p_tool[-1] - p_handle[-1]))
    if grasped:
        p_TG = np.array(p_held)[times >= t_pull]
        max_drift = float(np.linalg.norm(p_TG - p_TG[0], axis=1).max())
    revolute = joint.type_name() == "revolute"
    joint_error = abs(q_obj[-1] - q_target) * abs(span)
    tolerance = config.revolute_tolerance if revolute else config.prismatic_tolerance
    success = grasped and joint_error <= tolerance and max_drift <= config.drift_tolerance
    return SimulationResult(success, grasped, "revolute" if revolute else "prismatic", q_target,
                            float(q_obj[-1]), float(joint_error), grasp_offset, max_drift,
                            float(max(forces)) if forces else 0.0, times, np.array(q_obj), p_tool, p_handle,
                            config.grasp, shortfall,
                            pull_to_stop.stopped_at(context)[1] if to_stop and grasped else float("nan"),
                            misses + 1, turned, q_pulled, gap, plant.GetPositions(plant_context, robot),
                            pull_line, t_pull if grasped else float("nan"))


def hydroelastic_grip(plant: MultibodyPlant, scene_graph, pads, held) -> None:
    """Compliant hydroelastic finger pads on the collision geometries of the bodies `pads` (modulus
    `PAD_MODULUS`, 4 mm resolution) and rigid hydroelastic ones on those of `held` (what they
    squeeze: the handle's bodies; an item is compliant itself), friction 1; before Finalize.
    With point contact the squeezed pads sank about a centimetre into an item and squeezed it
    out."""
    for bodies, compliant in ((pads, True), (held, False)):
        for g in [g for body in bodies for g in plant.GetCollisionGeometriesForBody(body)]:
            props = ProximityProperties()
            AddContactMaterial(dissipation=1.0, friction=CoulombFriction(1.0, 1.0), properties=props)
            if compliant:
                AddCompliantHydroelasticProperties(0.004, PAD_MODULUS, props)
            else:
                AddRigidHydroelasticProperties(0.004, props)
            scene_graph.AssignRole(plant.get_source_id(), g, props, RoleAssign.kReplace)


def rigid_hydroelastic(plant: MultibodyPlant, scene_graph, bodies) -> None:
    """Rigid hydroelastic collision geometries for `bodies`, their friction kept (what a
    compliant hydroelastic item, `nfr_drake.world.items`, rests on); before Finalize."""
    inspector = scene_graph.model_inspector()
    for g in [g for body in bodies for g in plant.GetCollisionGeometriesForBody(body)]:
        props = ProximityProperties(inspector.GetProximityProperties(g))
        AddRigidHydroelasticProperties(0.004, props)
        scene_graph.AssignRole(plant.get_source_id(), g, props, RoleAssign.kReplace)


START_PENETRATION_M = 0.005
"""`robot_inside`: the robot's start may touch the object this deep, m."""


class StartsInsideObject(NfrDrakeError):
    """The plan starts with the robot (its base column or a link) inside the true object: its
    base was placed where the keypoints' boxes left room and the object is not. Such a start is
    refused before simulating (a real robot could not stand there; simulated, a lift column in a
    locked part crashed the process, `add_pedestal`)."""


def robot_inside(plant: MultibodyPlant, scene_graph, root_context, robot, model,
                 tolerance: float = START_PENETRATION_M) -> str | None:
    """Where the robot (model instance `robot` and the lift column, `add_pedestal`) penetrates the
    object (model instance `model`) more than `tolerance` at the state in `root_context` (the
    diagram's), the deepest pair in words; None when nowhere."""
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root_context))
    inspector = query.inspector()

    def body(geometry):
        return plant.GetBodyFromFrameId(inspector.GetFrameId(geometry))

    def owner(geometry) -> object:
        return body(geometry).model_instance()

    def name(geometry) -> str:
        return body(geometry).name() if owner(geometry) == robot else inspector.GetName(geometry)

    deepest = None
    for pair in query.ComputePointPairPenetration():
        for ours, theirs in ((pair.id_A, pair.id_B), (pair.id_B, pair.id_A)):
            robot_side = owner(ours) == robot or body(ours).name() == PEDESTAL_NAME
            if robot_side and owner(theirs) == model and pair.depth > tolerance:
                if deepest is None or pair.depth > deepest[0]:
                    deepest = (pair.depth, name(ours), name(theirs))
    if deepest is None:
        return None
    return (f"the robot starts inside the object ({deepest[1]} in {deepest[2]}): its base stands where "
            "the planner's obstacle boxes left room and the object is not")


def lock_shut(plant: MultibodyPlant, plant_context, joints) -> None:
    """Set one-dof `joints` to 0 (shut) and lock them in `plant_context` (`Joint.Lock`; SAP keeps a
    locked joint still whatever pushes it). Locking instead of welding keeps the object's model as
    it is everywhere else, and a later run may leave the joints free."""
    for joint in joints:
        set_joint_value(plant, plant_context, joint, 0.0)
        joint.Lock(plant_context)


def grip_points(p_BH: np.ndarray, bar_B: np.ndarray, half_length: float, spacing: float) -> np.ndarray:
    """Candidate grip points (n, 3) in the handle body's frame: p_BH, and for a bar (half_length
    > 0) points every `spacing` or less along unit bar_B within half_length of it, m."""
    n = 2 * int(np.ceil(half_length / spacing)) + 1 if half_length > 0.0 else 1
    return p_BH + np.linspace(-half_length, half_length, n)[:, None] * bar_B


def _force_on_moving_part(plant: MultibodyPlant, plant_context, bodies, joint) -> float:
    """|sum_i m_i (a_i - g) - F_joint| over the moving bodies: the force on the moving part from
    everything but gravity and its joint (the hand, and any contact), N."""
    A = plant.get_body_spatial_accelerations_output_port().Eval(plant_context)
    total = np.zeros(3)
    for body in bodies:
        V_WB = plant.EvalBodySpatialVelocityInWorld(plant_context, body)
        X_WB = plant.EvalBodyPoseInWorld(plant_context, body)
        p_BoBcm_W = X_WB.rotation() @ body.CalcCenterOfMassInBodyFrame(plant_context)
        a_cm = A[body.index()].Shift(p_BoBcm_W, V_WB.rotational()).translational()
        total += body.get_mass(plant_context) * (a_cm - _G)
    F_reaction = plant.get_reaction_forces_output_port().Eval(plant_context)[int(joint.index())]
    R_WJc = joint.frame_on_child().CalcPoseInWorld(plant_context).rotation()
    return float(np.linalg.norm(total - R_WJc @ F_reaction.translational()))
