"""Why an open-and-place run of a capture object failed, traced in the simulation (true keypoints,
contact grasp; docs/PLACE.md, "Results").

    python scripts/place_diagnosis.py door INDEX         # closet INDEX of seed 200: who pushes the door
    python scripts/place_diagnosis.py item INDEX T0 T1   # the item's and the hand's contacts, T0-T1 s
    python scripts/place_diagnosis.py carry INDEX        # the planned carry's clearance, densely
    python scripts/place_diagnosis.py fitted INDEX [SEED] [RADIUS] # the item near the goal, field keypoints

`door`: the opening alone, simulated; at each sample where the force on the door exceeds 150 N
(and every 25th), the contact forces on it by body pair, N. `item`: the whole task; between T0 and
T1 s of the place's simulation, the hand's position (m) and the item's contact forces by body
pair. `carry`: the place planned as the task plans it (the opening simulated first), then the
held item's nearest distance to the true compartment at 3000 times along the carry, cm, and the
smallest. `fitted`: closet INDEX of capture SEED (default 200) through the whole pipeline as
`eval-pipeline --task open-and-place --grasp contact` runs it (ten photos, the field's keypoints):
the fitted keypoints' errors at the target, cm; the item's planned pose at the release (its tilt,
degrees); every 0.1 s while the item lies within RADIUS m (default 0.15) of the true goal
(horizontally), its position and the tool's (m) and the item's contact forces by body pair, N
(RADIUS 10: all along the place, where the item was lost on its way).
"""

from __future__ import annotations

import sys

import numpy as np
from pydrake.systems.analysis import Simulator

import nfr_drake.systems.articulation as articulation
import nfr_drake.systems.place_task as place_task
from nfr_drake.planning.planner import PlannerConfig, grasp_planner, plan_articulation
from nfr_drake.planning.scene import build_planning_scene
from nfr_drake.systems.articulation import SimulationConfig
from nfr_drake.systems.scenario import Scenario
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.world.keypoints import KeypointTrajectory

CONTACT = place_task.PlaceSimulationConfig(opening=SimulationConfig(grasp="contact"))


def contact_forces(plant, context) -> dict[tuple[str, str], float]:
    """Contact force magnitudes (hydroelastic and point) summed by body pair (names), N."""
    results = plant.get_contact_results_output_port().Eval(context)
    inspector = plant.get_geometry_query_input_port().Eval(context).inspector()
    pairs: dict[tuple[str, str], float] = {}
    for i in range(results.num_hydroelastic_contacts()):
        info = results.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        names = tuple(sorted(plant.GetBodyFromFrameId(inspector.GetFrameId(g)).name()
                             for g in (surface.id_M(), surface.id_N())))
        pairs[names] = pairs.get(names, 0.0) + float(np.linalg.norm(info.F_Ac_W().translational()))
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        names = tuple(sorted(plant.get_body(b).name() for b in (info.bodyA_index(), info.bodyB_index())))
        pairs[names] = pairs.get(names, 0.0) + float(np.linalg.norm(info.contact_force()))
    return pairs


def door(index: int) -> None:
    scenario = Scenario(category="closet", seed=200, index=index, q_target=0.6)
    obj, part = scenario.sample_piece()
    kt = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0, part=part)
    plan = plan_articulation(kt, 0.6, config=grasp_planner(PlannerConfig(), "contact"))
    force_on = articulation._force_on_moving_part
    count = [0]

    def traced(plant, context, bodies, joint):
        force = force_on(plant, context, bodies, joint)
        count[0] += 1
        if force > 150.0 or count[0] % 25 == 0:
            pairs = {k: round(v) for k, v in contact_forces(plant, context).items() if v > 1.0}
            print(f"t {context.get_time():.2f} s, door joint {joint.GetOnePosition(context):.3f}, "
                  f"force {force:.0f} N: {pairs}")
        return force

    articulation._force_on_moving_part = traced
    scene_object = SceneObject.from_articulated_object(obj, scenario.X_WO, 0.0, part)
    print(articulation.simulate_articulation(scene_object, plan, 0.6, None, CONTACT.opening).summary())


def item(index: int, t0: float, t1: float) -> None:
    class Tracing(Simulator):
        def AdvanceTo(self, t):
            status = super().AdvanceTo(t)
            plant = self.get_system().GetSubsystemByName("plant")
            if t0 <= t <= t1 and plant.num_bodies() > 0 and plant.HasBodyNamed("item"):
                context = plant.GetMyContextFromRoot(self.get_context())
                hand = plant.GetFrameByName("panda_hand").CalcPoseInWorld(context).translation()
                pairs = {k: round(v) for k, v in contact_forces(plant, context).items() if v > 0.5}
                print(f"t {t:.2f} s, hand {np.round(hand, 3)} m: {pairs}")
            return status

    place_task.Simulator = Tracing
    scenario = Scenario(category="closet", seed=200, index=index, q_target=0.6)
    obj, _ = scenario.sample_piece()
    outcome = place_task.run_place_task(obj, scenario.X_WO, 0.0, 0.6, scenario.sample_item(),
                                        simulation_config=CONTACT)
    print(outcome.planning_error or outcome.simulation.summary())


def carry(index: int) -> None:
    scenario = Scenario(category="closet", seed=200, index=index, q_target=0.6)
    obj, _ = scenario.sample_piece()
    held = scenario.sample_item()
    planned = {}

    def stop(obj_, X_WO, opening, place, *rest, **kwargs):
        planned.update(place=place, q_door=opening.q_final)
        raise StopIteration

    place_task.simulate_place = stop
    try:
        outcome = place_task.run_place_task(obj, scenario.X_WO, 0.0, 0.6, held, simulation_config=CONTACT)
        print(outcome.planning_error)
        return
    except StopIteration:
        pass
    place = planned["place"]
    fixed, moving = place_task.true_compartment(obj, scenario.X_WO, planned["q_door"])
    scene = build_planning_scene(place.X_WB, [*fixed, *moving], (held, place.X_GI))
    segment = place.segments[1]
    closest = []
    for t in np.linspace(0.0, segment.duration, 3000):
        scene.plant.SetPositions(scene.plant_context, segment.value(t))
        query = scene.plant.get_geometry_query_input_port().Eval(scene.plant_context)
        names = query.inspector().GetName
        near = [(p.distance, names(p.id_A), names(p.id_B))
                for p in query.ComputeSignedDistancePairwiseClosestPoints(0.05)
                if any("held" in names(g) for g in (p.id_A, p.id_B))]
        if near:
            closest.append((t, *min(near)))
    for t, d, a, b in closest[::20]:
        print(f"t {t:6.2f} s: {100 * d:6.2f} cm, {a} - {b}")
    t, d, a, b = min(closest, key=lambda c: c[1])
    print(f"smallest: {100 * d:.2f} cm at {t:.2f} s into the carry, {a} - {b}")


def fitted(index: int, seed: int, radius: float) -> None:
    from nfr_drake.eval.pipeline_eval import object_scenario
    from nfr_drake.systems.pipeline import run_scenario

    class Tracing(Simulator):
        def AdvanceTo(self, t):
            status = super().AdvanceTo(t)
            plant = self.get_system().GetSubsystemByName("plant")
            if round(100 * t) % 10 == 0 and plant.HasBodyNamed("item"):
                context = plant.GetMyContextFromRoot(self.get_context())
                p = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName("item")).translation()
                if np.linalg.norm((p - goal)[:2]) < radius:
                    tool = plant.GetFrameByName("panda_tool").CalcPoseInWorld(context).translation()
                    pairs = {k: round(v, 1) for k, v in contact_forces(plant, context).items() if v > 0.2}
                    print(f"t {t:.2f} s, item {np.round(p, 3)}, tool {np.round(tool, 3)} m: {pairs}")
            return status

    place_task.Simulator = Tracing
    base = Scenario(category="closet", seed=seed, index=index, q_target=0.6, task="open-and-place",
                    grasp="contact")
    scenario = object_scenario(base, index)
    obj, part = scenario.sample_piece()
    goal = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0, part=part).point("goal", 0.6)
    outcome = run_scenario(scenario)
    task, fit, truth = outcome.task, outcome.predicted, outcome.truth
    for name in fit.names:
        error = 100 * (fit.point(name, 0.6) - truth.point(name, 0.6))
        print(f"fitted {name} - true at 0.6: {np.round(error, 2)} cm")
    if task.place is None:
        print(task.planning_error)
        return
    X_WI = task.place.X_WI_place
    tilt = np.degrees(np.arccos(X_WI.rotation().col(2)[2]))
    print(f"planned release: item at {np.round(X_WI.translation(), 3)} m, tilted {tilt:.1f} deg")
    print(task.simulation.summary())


if __name__ == "__main__":
    mode, args = sys.argv[1], sys.argv[2:]
    {"door": lambda: door(int(args[0])), "item": lambda: item(int(args[0]), float(args[1]), float(args[2])),
     "carry": lambda: carry(int(args[0])),
     "fitted": lambda: fitted(int(args[0]), int(args[1]) if len(args) > 1 else 200,
                              float(args[2]) if len(args) > 2 else 0.15)}[mode]()
