"""Loading articulated objects into a Drake MultibodyPlant, with their semantic render labels."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import PerceptionProperties, RenderLabel, Role, RoleAssign, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from nfr_drake.objects.articulated import ArticulatedObject, part_semantic_class
from nfr_drake.objects.sdformat import to_sdformat


def add_articulated_object(
    plant: MultibodyPlant,
    obj: ArticulatedObject,
    X_WO: RigidTransform | None = None,
    model_name: str | None = None,
) -> ModelInstanceIndex:
    """Parse `obj` into `plant` and weld its carcass to the world at X_WO (default identity).

    Must be called before `plant.Finalize()`.
    """
    parser = Parser(plant)
    if model_name is not None:
        parser.SetAutoRenaming(False)
    sdf = to_sdformat(obj)
    if model_name is not None:
        sdf = sdf.replace(f'<model name="{obj.name}">', f'<model name="{model_name}">', 1)
    (model,) = parser.AddModelsFromString(sdf, "sdf")
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName(obj.base_link_name, model),
        X_WO if X_WO is not None else RigidTransform(),
    )
    return model


def set_articulation(plant: MultibodyPlant, plant_context, obj: ArticulatedObject,
                     model: ModelInstanceIndex, q: float) -> None:
    """Set the object's joint to articulation q in [0, 1]."""
    plant.SetPositions(plant_context, model, np.array([obj.joint_value(q)]))


def apply_semantic_labels(plant: MultibodyPlant, scene_graph: SceneGraph,
                          model: ModelInstanceIndex) -> None:
    """Give each perception geometry of `model` the RenderLabel of its semantic class.

    Geometry names carry their class (see `Part.geometry_name`). Call before creating a context.
    """
    inspector = scene_graph.model_inspector()
    source_id = plant.get_source_id()
    for body_index in plant.GetBodyIndices(model):
        frame_id = plant.GetBodyFrameIdOrThrow(body_index)
        for geometry_id in inspector.GetGeometries(frame_id, Role.kPerception):
            label = int(part_semantic_class(inspector.GetName(geometry_id)))
            props = PerceptionProperties(inspector.GetPerceptionProperties(geometry_id))
            props.UpdateProperty("label", "id", RenderLabel(label))
            # Perception properties cannot be replaced in place: remove the role, assign anew.
            scene_graph.RemoveRole(source_id, geometry_id, Role.kPerception)
            scene_graph.AssignRole(source_id, geometry_id, props, RoleAssign.kNew)
