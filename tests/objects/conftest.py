"""Shared by the object tests: an object loaded into its own MultibodyPlant."""

import pytest
from pydrake.geometry import Role
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.objects.plant import add_articulated_object, set_articulation


class LoadedObject:
    """An object in its own plant, with geometry poses queryable by part name."""

    def __init__(self, obj):
        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        self.model = add_articulated_object(self.plant, obj)
        self.plant.Finalize()
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyMutableContextFromRoot(self.context)
        self.obj = obj

    def set_q(self, q):
        set_articulation(self.plant, self.plant_context, self.obj, self.model, q)

    def geometry_pose(self, local_name):
        """X_WG (4x4) of the visual geometry whose name ends with `local_name`."""
        sg_context = self.scene_graph.GetMyContextFromRoot(self.context)
        query = self.scene_graph.get_query_output_port().Eval(sg_context)
        inspector = query.inspector()
        for gid in inspector.GetAllGeometryIds(Role.kIllustration):
            if inspector.GetName(gid).endswith("::" + local_name):
                return query.GetPoseInWorld(gid).GetAsMatrix4()
        raise KeyError(local_name)


@pytest.fixture
def load_object():
    """Loads an `ArticulatedObject` into its own plant: `load_object(obj) -> LoadedObject`."""
    return LoadedObject
