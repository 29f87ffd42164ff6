"""A Drake system that outputs an object's keypoint trajectory with its present articulation."""

from __future__ import annotations

from pydrake.common.value import Value
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Joint
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from nfr_drake.world.keypoints import KeypointTrajectory


class KeypointTrajectorySource(LeafSystem):
    """Reads the object's joint from the plant state and outputs its `KeypointTrajectory`.

    The keypoint positions along q come from `trajectory` (ground truth here, the neural field's
    forward simulation later); q_current is the joint position mapped onto [0, 1] by its shut and
    open values (default: its lower and upper limits).
    The carcass must be welded to the world (the grid positions are in W and do not move).

    .. pydrake_system::

        name: KeypointTrajectorySource
        input_ports:
        - plant_state
        output_ports:
        - keypoint_trajectory

    plant_state: the full state of `plant` (its `get_state_output_port()`).
    keypoint_trajectory: an abstract `KeypointTrajectory`.
    """

    def __init__(self, plant: MultibodyPlant, joint: Joint, trajectory: KeypointTrajectory,
                 shut_and_open: tuple[float, float] | None = None):
        super().__init__()
        self._trajectory = trajectory
        self._position_index = joint.position_start()
        shut, opened = shut_and_open or (joint.position_lower_limits()[0], joint.position_upper_limits()[0])
        self._lower, self._range = float(shut), float(opened) - float(shut)
        self._state_port = self.DeclareVectorInputPort(
            "plant_state", plant.num_multibody_states())
        self._output_port = self.DeclareAbstractOutputPort(
            "keypoint_trajectory", lambda: Value(trajectory), self._CalcKeypointTrajectory,
            prerequisites_of_calc={self._state_port.ticket()})

    def get_plant_state_input_port(self):
        return self._state_port

    def get_keypoint_trajectory_output_port(self):
        return self._output_port

    def _CalcKeypointTrajectory(self, context, output) -> None:
        joint_value = self._state_port.Eval(context)[self._position_index]
        q = (joint_value - self._lower) / self._range
        output.set_value(self._trajectory.with_current(q))


def AddKeypointTrajectorySource(builder: DiagramBuilder, plant: MultibodyPlant, joint: Joint,
                                trajectory: KeypointTrajectory,
                                shut_and_open: tuple[float, float] | None = None) -> KeypointTrajectorySource:
    """Add a `KeypointTrajectorySource` fed by `plant`'s state (the joint's values at q = 0 and 1:
    `shut_and_open`, default its limits); returns the system."""
    system = builder.AddNamedSystem("keypoint_trajectory",
                                    KeypointTrajectorySource(plant, joint, trajectory, shut_and_open))
    builder.Connect(plant.get_state_output_port(), system.get_plant_state_input_port())
    return system
