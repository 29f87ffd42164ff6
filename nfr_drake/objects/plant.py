"""Loading articulated objects into a Drake MultibodyPlant, with their semantic render labels."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import PerceptionProperties, RenderLabel, Role, RoleAssign, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from nfr_drake.objects.articulated import ArticulatedObject, render_label_value
from nfr_drake.objects.sdformat import to_sdformat
from nfr_drake.parsing import make_parser


def add_articulated_object(
    plant: MultibodyPlant,
    obj: ArticulatedObject,
    X_WO: RigidTransform | None = None,
    model_name: str | None = None,
) -> ModelInstanceIndex:
    """Parse `obj` into `plant` and weld its carcass to the world at X_WO (default identity).

    Must be called before `plant.Finalize()`.
    """
    parser = make_parser(plant)
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
                     model: ModelInstanceIndex, q: float | np.ndarray) -> None:
    """Set the object's joints to articulation q in [0, 1]: one value for all fronts, or shape (F,)."""
    positions = plant.GetPositions(plant_context)
    for front, value in zip(obj.fronts, obj.joint_values(q), strict=True):
        positions[plant.GetJointByName(front.joint_name, model).position_start()] = value
    plant.SetPositions(plant_context, positions)


def apply_semantic_labels(plant: MultibodyPlant, scene_graph: SceneGraph,
                          model: ModelInstanceIndex) -> None:
    """Give each perception geometry of `model` its RenderLabel: class and front index.

    Geometry names carry both (`render_label_value`: 1 for the carcass, class + 4 (k + 1) for
    the parts of front k). Call before creating a context.
    """
    inspector = scene_graph.model_inspector()
    source_id = plant.get_source_id()
    for body_index in plant.GetBodyIndices(model):
        frame_id = plant.GetBodyFrameIdOrThrow(body_index)
        for geometry_id in inspector.GetGeometries(frame_id, Role.kPerception):
            label = render_label_value(inspector.GetName(geometry_id))
            props = PerceptionProperties(inspector.GetPerceptionProperties(geometry_id))
            props.UpdateProperty("label", "id", RenderLabel(label))
            # Perception properties cannot be replaced in place: remove the role, assign anew.
            scene_graph.RemoveRole(source_id, geometry_id, Role.kPerception)
            scene_graph.AssignRole(source_id, geometry_id, props, RoleAssign.kNew)


def self_penetrations(obj: ArticulatedObject, q: float | np.ndarray, tolerance: float = 5e-4
                      ) -> list[tuple[str, str, float]]:
    """Pairs of the object's collision geometries on different links that overlap at articulation q.

    Unlike a simulation, the carcass is checked against every front too (MultibodyPlant filters
    a joint's parent and child). Returns (geometry name, geometry name, depth in m) of every pair
    deeper than `tolerance` (m).
    """
    from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    model = add_articulated_object(plant, obj)
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    link_sets = [GeometrySet(inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(b), Role.kProximity))
                 for b in plant.GetBodyIndices(model)]
    manager = scene_graph.collision_filter_manager()
    for i, a in enumerate(link_sets):
        for b in link_sets[i + 1:]:
            manager.Apply(CollisionFilterDeclaration().AllowBetween(a, b))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    set_articulation(plant, plant.GetMyMutableContextFromRoot(context), obj, model, q)
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    return [(inspector.GetName(p.id_A), inspector.GetName(p.id_B), float(p.depth))
            for p in query.ComputePointPairPenetration() if p.depth > tolerance]
