"""A scenario: one task in simulation, as a dataclass a user edits in YAML (`systems/*.yaml`).

Loaded with Drake's `yaml_load_typed` (`Scenario.load`); fields left out keep their defaults. This
module keeps real (not postponed) annotations, which `yaml_load_typed` needs to read field types.
"""

import typing
from dataclasses import asdict, dataclass, field, fields, make_dataclass
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed
from pydrake.math import RigidTransform, RotationMatrix

from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import PAINTINGS, checked_paintings
from nfr_drake.objects import (
    SEED_DOMAIN_CAPTURE,
    SEED_DOMAIN_TRAIN,
    ArticulatedObject,
    object_rng,
    sample_object,
)
from nfr_drake.perception.segmentation.crop import AimedLook
from nfr_drake.planning.planner import PlannerConfig
from nfr_drake.systems.articulation import GRASPS, SimulationConfig
from nfr_drake.systems.scene_objects import SceneObject, object_pose, random_part
from nfr_drake.world.items import Item, sample_item

_ITEM_STREAM = 23  # the item's random stream beside the object's (the number)
_COARSE_LOOK_STREAM = 20  # the coarse look's random stream (the number)
OBJECT_DOMAINS = {"capture": SEED_DOMAIN_CAPTURE, "train": SEED_DOMAIN_TRAIN}
KEYPOINT_SOURCES = ("head", "geometry", "ground_truth")
TASKS = ("open", "open-and-place")
OBJECT_POSE_SOURCES = ("given", "estimated")
PERCEPTION_SCENES = ("alone", "room")
ROOM_LOSSES = ("background", "masked")


@dataclass
class Scenario:
    """One task: an object, where it stands, the articulation to reach and where the planner's
    keypoints come from."""

    category: str = "closet"
    """"closet", "drawer" or "furniture" (a piece with several doors and drawers, one of them
    opened, `part`)."""
    objects: str = "capture"
    """Which objects: "capture" (unseen ones, `object_rng(SEED_DOMAIN_CAPTURE, seed, index)`, never
    a training object) or "train" (`object_rng(SEED_DOMAIN_TRAIN, seed, index)`)."""
    seed: int = 100
    """Seed of the object."""
    index: int = 0
    """Object index within the seed."""
    q_start: float = 0.0
    """The object's articulation at the start (when photographed), in [0, 1]."""
    q_target: float = 1.0
    """The articulation to reach, in [0, 1] (1 opens, 0 closes)."""
    object_xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    """Position of the object frame O in W, m."""
    object_yaw_deg: float = 0.0
    """Rotation of O about W's z, degrees."""
    keypoints: str = "head"
    """Where the planner's keypoints come from: the neural field fitted to photos of Drake cameras,
    "head" (its keypoint head, as in the paper; the better of the two on unseen objects,
    docs/EVALUATION.md) or "geometry" (handle and hinge axis read from the fitted field's
    segmentation); or "ground_truth" (the object's own model: no cameras, no fit)."""
    model: str = "models/closet"
    """Neural-field model folder of the category (not read with ground-truth keypoints)."""
    views: int = 10
    """Perception cameras."""
    image_size: int = 128
    """Square image size of the perception cameras, pixels. 128 by default: the models were
    trained on 64 px images, but the fit takes any resolution, and with the shipped models 128 px
    opens more objects (docs/EVALUATION.md, "The whole pipeline")."""
    fov_y_deg: float = 50.0
    """Vertical field of view of the perception cameras, degrees."""
    distance_m: list[float] = field(default_factory=lambda: [1.4, 1.9])
    """Distance range of the perception cameras to the object centre, m."""
    fit: FitConfig = field(default_factory=FitConfig)
    """Options of the neural field's fit (closets and drawers; furniture is fitted with the defaults
    of `FurnitureFitConfig`)."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    """Options of the planner."""
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    """Options of the simulation."""
    replay: str = ""
    """HTML replay to write ("" for none)."""
    min_confidence: float = -1.0
    """The planner acts only on a fit whose P(handle within 2 cm) (`inference.confidence`) is at
    least this: below 0, the threshold of the model's calibration (`confidence.json`; a model
    without one is never refused); 0, never refused; 1, always refused."""
    task: str = "open"
    """"open" (reach q_target) or "open-and-place" (then pick an item, `sample_item` from the
    object's seed and index, from a table beside the robot and place it at the goal keypoint)."""
    grasp: str = "constraint"
    """How the simulated hand holds the handle (and the item): "constraint" (constraints switched
    on when the fingers close, the arm compliant while it pulls) or "contact" (the fingers squeeze,
    friction holds, the arm at full stiffness). It sets `simulation.grasp` and the planner's
    options for that grasp (`planning.planner.grasp_planner`: grip depth, and for contact the
    rigid hold and no end-stop overshoot)."""
    object_pose: str = "given"
    """Where the perception system's X_WO comes from: "given" (the true pose, the paper's setting)
    or "estimated" (from the views' masks, `perception.object_pose`); estimated, the cameras are
    placed around a coarse look at the scene, the true pose off by `coarse_look_m` (xy) and
    `coarse_look_deg` (yaw), drawn from the seed, instead of around the true object."""
    coarse_look_m: float = 0.1
    """Standard deviation of the coarse look's position error along x and y, m."""
    coarse_look_deg: float = 10.0
    """Standard deviation of the coarse look's yaw error, degrees."""
    perceive: str = "alone"
    """What the perception cameras see: "alone", the object before the training renders'
    background and lights (the paper's setting), or "room", the object in a random room drawn
    from the seed and index (floor, walls, other furniture, clutter, the arm; the held-out textures
    and lights, which the segmenter never saw, `nfr_drake.data.rooms`), its masks found by
    `segmenter` (`room_loss` says what the fit does with them)."""
    segmenter: str = "models/segmenter"
    """Segmenter model folder (read when perceiving a room)."""
    room_loss: str = "background"
    """Perceiving a room, what the fit does with the photos' pixels off the object's mask:
    "background", painted in the training background (the field's silhouette must match the
    mask), or "masked", left out of the image loss (`systems.perception.RoomLoss`)."""
    paintings: list[str] = field(default_factory=lambda: list(PAINTINGS))
    """Perceiving a room with `room_loss` "background", how the photos are painted: one fit per
    painting ("region", "fronts", "sure": `inference.infer.Painting`; by default all three), the
    one with the highest P(handle within 2 cm) kept (`NfrPerceptionSystem`)."""
    mask_crop: bool = True
    """Perceiving a room, whether the segmenter takes a second, close look at the crop around the
    object's box estimated from its first masks, and at the crop around its carcass's box for the
    amodal carcass masks that give the pose (`perception.segmentation.crop`)."""
    aimed_look: str = "off-aim"
    """Perceiving a room with `mask_crop` and an estimated pose, when the segmenter's look at the
    crop around where the cameras aim gives the pose and masks: "off-aim" (where the whole photos'
    pose is not of the object aimed at, or none), "always" or "never"
    (`perception.segmentation.crop.AimedLook`)."""
    look_again: bool = True
    """Perceiving a room with `mask_crop` and an estimated pose: a fit its confidence refuses is
    followed by one at the other look (the aimed look after whole photos, or the reverse), the more
    confident kept (`NfrPerceptionSystem`)."""
    refine_masks: bool = False
    """Perceiving a room with `room_loss` "background": the pixels of the segmenter's masks that the
    photo's colours call background (GrabCut started from its probabilities) are taken off them
    before the photos are painted (`perception.segmentation.refine`). Off by default: better masks
    and closet poses, fewer objects opened (docs/ROOMS.md, "Mask edges by the photo's colours")."""
    part: int = -1
    """Furniture: the part to open (its index in canonical order, docs/FURNITURE.md), the others
    held shut; -1 draws one from the piece's own random stream after the piece, as the planning
    evaluation does (`sample_piece`). A closet or a drawer has part 0 alone."""
    object_file: str = ""
    """A user's SDFormat or URDF model to perceive and open instead of a generated object ("" for
    none): the door or drawer on `joint`, its handle the centre of `handle_body`'s geometry, placed
    by `object_xyz`, `object_yaw_deg` and `object_rpy_deg` (`SceneObject.from_model_file`, whose
    refusals say what to change). Photographed alone, fitted with `model` ("" for
    models/furniture; a closet or drawer model must be of the joint's kind: the joint decides, not
    `category`) in the frame O its carcass gives (`SceneObject.category_frame`) or, with
    `object_pose` "estimated", in the frame estimated from the photos; then opened."""
    joint: str = ""
    """`object_file`: the joint of the door or drawer to open."""
    handle_body: str = ""
    """`object_file`: the body whose geometry's centre is the handle."""
    closed_at: str = ""
    """`object_file`: which limit of `joint` is shut, "lower" or "upper" ("" for the rule of
    docs/PLANNING.md, "Users' model files")."""
    object_rpy_deg: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    """`object_file`: roll, pitch, yaw of the model in W, degrees, before `object_yaw_deg` (a model
    drawn lying on its side: 90 0 0 stands a Y-up export up)."""

    def __post_init__(self):
        if self.category not in ("closet", "drawer", "furniture"):
            raise ConfigError(f"category must be closet, drawer or furniture, got {self.category!r}")
        if self.category != "furniture" and self.part not in (-1, 0):
            raise ConfigError(f"part {self.part}: a {self.category} has one part, 0")
        if self.category == "furniture" and self.task != "open":
            raise ConfigError(f"task {self.task!r}: furniture is opened only (task open)")
        if self.objects not in OBJECT_DOMAINS:
            raise ConfigError(f"objects must be one of {sorted(OBJECT_DOMAINS)}, got {self.objects!r}")
        for name in ("q_start", "q_target"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"{name} must lie in [0, 1]")
        if self.keypoints not in KEYPOINT_SOURCES:
            raise ConfigError(f"keypoints must be one of {', '.join(KEYPOINT_SOURCES)}, "
                              f"got {self.keypoints!r}")
        if self.task not in TASKS:
            raise ConfigError(f"task must be one of {', '.join(TASKS)}, got {self.task!r}")
        if self.grasp not in GRASPS:
            raise ConfigError(f"grasp must be one of {', '.join(GRASPS)}, got {self.grasp!r}")
        if self.object_pose not in OBJECT_POSE_SOURCES:
            raise ConfigError(f"object_pose must be one of {', '.join(OBJECT_POSE_SOURCES)}, "
                              f"got {self.object_pose!r}")
        if self.perceive not in PERCEPTION_SCENES:
            raise ConfigError(f"perceive must be one of {', '.join(PERCEPTION_SCENES)}, "
                              f"got {self.perceive!r}")
        if self.room_loss not in ROOM_LOSSES:
            raise ConfigError(f"room_loss must be one of {', '.join(ROOM_LOSSES)}, got {self.room_loss!r}")
        checked_paintings(self.paintings)
        if self.aimed_look not in typing.get_args(AimedLook):
            raise ConfigError(f"aimed_look must be one of {', '.join(typing.get_args(AimedLook))}, "
                              f"got {self.aimed_look!r}")
        if not (self.coarse_look_m >= 0.0 and self.coarse_look_deg >= 0.0):
            raise ConfigError("coarse_look_m and coarse_look_deg must be >= 0")
        if self.min_confidence > 1.0:
            raise ConfigError("min_confidence must be at most 1 (below 0: the calibrated threshold)")
        if self.views < 1 or self.image_size < 8:
            raise ConfigError("views must be >= 1 and image_size >= 8")
        object_pose(self.object_xyz, self.object_yaw_deg, self.object_rpy_deg)  # ConfigError if not finite
        if self.object_file:
            if not (self.joint and self.handle_body):
                raise ConfigError("object_file needs joint and handle_body")
            if self.task != "open" or self.perceive != "alone":
                raise ConfigError("a model file (object_file) is perceived alone and opened: task open, "
                                  "perceive alone")
            if self.closed_at not in ("", "lower", "upper"):
                raise ConfigError(f"closed_at must be lower, upper or empty, got {self.closed_at!r}")
        elif self.joint or self.handle_body or self.closed_at or any(self.object_rpy_deg):
            raise ConfigError("joint, handle_body, closed_at and object_rpy_deg apply to a model file "
                              "(object_file)")

    @classmethod
    def load(cls, path: Path) -> "Scenario":
        """The scenario in a YAML file, read with `yaml_load_typed` (unknown keys are errors)."""
        loaded = yaml_load_typed(schema=_ScenarioFile, filename=str(path))
        values = {f.name: getattr(loaded, f.name) for f in fields(cls)}
        values["fit"] = FitConfig(**asdict(loaded.fit))
        return cls(**values)

    @property
    def perceives(self) -> bool:
        """Whether the keypoints come from the neural field (cameras and a fit)."""
        return self.keypoints != "ground_truth"

    @property
    def X_WO(self) -> RigidTransform:
        """The object's pose in W: frame O of a generated object, the model's own frame of a
        model file (`object_file`)."""
        return object_pose(self.object_xyz, self.object_yaw_deg, self.object_rpy_deg)

    def coarse_look(self, X_WO: RigidTransform | None = None) -> RigidTransform:
        """Where the perception cameras are placed around: X_WO (default: the scenario's), or with
        an estimated pose that one off by the coarse look's errors (drawn from the seed and
        index) along W's x and y and about its z."""
        X_WO = self.X_WO if X_WO is None else X_WO
        if self.object_pose == "given":
            return X_WO
        rng = np.random.default_rng([self.seed, self.index, _COARSE_LOOK_STREAM])
        dx, dy = rng.normal(0.0, self.coarse_look_m, 2)
        turn = RotationMatrix.MakeZRotation(np.radians(rng.normal(0.0, self.coarse_look_deg)))
        return RigidTransform(turn @ X_WO.rotation(), X_WO.translation() + [dx, dy, 0.0])

    def model_file_object(self) -> SceneObject:
        """`object_file` loaded at q_start (`SceneObject.from_model_file`)."""
        return SceneObject.from_model_file(Path(self.object_file), self.joint, self.handle_body, self.X_WO,
                                           self.q_start, self.closed_at or None)

    def sample_object(self) -> ArticulatedObject:
        return self.sample_piece()[0]

    def sample_piece(self) -> tuple[ArticulatedObject, int]:
        """The object (`sample_object`) and the part to open: `part`, or with -1 one drawn from the
        object's stream after the object (`random_part`; 0 for a closet or a drawer). NfrDrakeError
        (`SceneObject.from_articulated_object`) later when the piece has no such part."""
        rng = object_rng(OBJECT_DOMAINS[self.objects], self.seed, self.index)
        obj = sample_object(self.category, rng, name=f"{self.category}_{self.seed}_{self.index}")
        return obj, (random_part(obj, rng) if self.part < 0 else self.part)

    def sample_item(self) -> Item:
        """The item an open-and-place task places: drawn from its own stream of the seed and index."""
        return sample_item(np.random.default_rng([self.seed, self.index, _ITEM_STREAM]))


def _thawed(cls: type) -> type:
    """A mutable dataclass with the fields, types and defaults of the frozen dataclass `cls`:
    `yaml_load_typed` fills a dataclass by setting its attributes one by one. It knows no
    `Literal`: such a field is read as the type of its values (`cls` checks the value); a field
    that may be None (`FitConfig.PRESETS`: None is the preset's value) is read as Optional."""
    def yaml_type(t):
        args = typing.get_args(t)
        if typing.get_origin(t) is typing.Literal:
            return type(args[0])
        if type(None) in args:
            (inner,) = [a for a in args if a is not type(None)]
            return typing.Optional[yaml_type(inner)]  # noqa: UP045 (what yaml_load_typed reads)
        return t

    hints = typing.get_type_hints(cls)
    return make_dataclass(cls.__name__, [(f.name, yaml_type(hints[f.name]), field(default=f.default))
                                         for f in fields(cls)])


_FitConfigFields = _thawed(FitConfig)


@dataclass
class _ScenarioFile(Scenario):
    """`Scenario` as `yaml_load_typed` reads it; `Scenario.load` turns `fit` into a `FitConfig`."""

    fit: _FitConfigFields = field(default_factory=_FitConfigFields)
