"""`nfr-drake explore`: what a neural field has learned (the paper's generative evaluation).

Four products, from the training codes of a model folder or from codes fitted to capture sets:
- `interpolation.png`: renders, segmentations and keypoints along the path between two objects,
  z_obj on a straight line and z_art on the unit circle (paper, Fig. "Interpolation of latent
  codes across articulation code and object code");
- `articulations.png`: one object at new articulations q in [0, 1] (forward simulation);
- `samples.png`: new objects, z_obj drawn from a Gaussian fitted to the training codes;
- `object.html`: a self-contained Meshcat page of one object: its labelled point cloud at its q
  and its keypoint trajectories over q, to turn around in a browser (offline).

A model of several part slots (furniture) is drawn slot by slot: an object has a q per slot,
each slot's z_art moves on its own circle along an interpolation, articulations.png sweeps one
part at a time with the others held, and the keypoints drawn are those of the parts the keypoint
head finds at the code (`object_parts`). All renders come from one camera per model, framing the
mean object (`model_view`).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Collection
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
import torch
import tyro
from tqdm import tqdm

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.capture import CaptureFrame, read_capture_set
from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.data.visualize import SEMANTIC_PALETTE, colorize_labels, pyplot
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.forward import (
    SimulatedView,
    keypoint_trajectory,
    render_view,
    semantic_point_cloud,
)
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import FittedModel, infer, infer_parts
from nfr_drake.inference.latent_space import CodeGaussian, farthest_code, interpolate_codes
from nfr_drake.inference.result import PART_KEYPOINTS
from nfr_drake.nfr.latent import ART_DIM, slots_q_to_z_art, split_z, z_art_to_q
from nfr_drake.perception.handle_triangulation import project
from nfr_drake.systems.replay import KEYPOINT_COLOURS, draw_keypoint_trajectory, frame_camera, write_replay
from nfr_drake.world.keypoints import PART_CATEGORY, KeypointTrajectory

VIEW_AZIMUTH_DEG = 30.0
VIEW_ELEVATION_DEG = 20.0
FOV_Y_DEG = 50.0
VIEW_FILL = 0.85
"""Share of the image height that the framed objects' bounding sphere spans in the figures."""
PROBE_DISTANCE_M = 2.2
"""Least distance of the low-resolution view that measures the framed objects (`model_view`), m."""
TRAJECTORY_POINTS = 21
"""Points of the q grid over [0, 1] of keypoint trajectories."""


def q_text(q: float | np.ndarray) -> str:
    """q as text: "0.11", or one per slot "0.96 0.00 0.20"."""
    return " ".join(f"{v:.2f}" for v in np.atleast_1d(np.asarray(q, float)))


@dataclass(frozen=True)
class ExploredObject:
    """An object in the model's code space: its name, z_obj (k,), articulation q in [0, 1] (a
    model of S part slots: one per slot, (S,)) and, for a fitted capture with ground truth, the
    capture's true q (a piece of furniture's: one per part, (M,)); a fitted piece of furniture's
    fit_parts: the parts its fit lists, as `nfr-drake infer` does ("0 drawer, 1 door")."""

    name: str
    z_obj: torch.Tensor
    q: float | np.ndarray
    true_q: float | np.ndarray | None = None
    fit_parts: str | None = None

    @property
    def qs(self) -> np.ndarray:
        """q per slot (S,) ((1,) for a one-part model)."""
        return np.atleast_1d(np.asarray(self.q, float))

    def describe(self) -> str:
        """Name and q, e.g. "fitted closet_000 (q 0.11, true 0.10)" (`q_text`)."""
        truth = "" if self.true_q is None else f", true {q_text(self.true_q)}"
        return f"{self.name} (q {q_text(self.q)}{truth})"

    @property
    def z(self) -> torch.Tensor:
        """The code (2 S + k,): per slot z_art = (cos(pi q), sin(pi q)), then z_obj."""
        qs = self.qs
        return torch.cat([slots_q_to_z_art(self.z_obj.new_tensor(qs)[None], len(qs))[0], self.z_obj])

    def with_slot(self, slot: int, q: float) -> ExploredObject:
        """This object with slot `slot` at q, the other slots held."""
        if np.ndim(self.q) == 0:
            return replace(self, q=float(q))
        qs = self.qs.copy()
        qs[slot] = q
        return replace(self, q=qs)


@dataclass(frozen=True)
class Part:
    """A part slot of a code as the keypoint head reads it: the slot, its kind ("door" or
    "drawer"; a one-part model's category), and its keypoints: names (K',) as the planner names
    them (`PART_KEYPOINTS`) and their indices (K',) among the head's K keypoints."""

    slot: int
    kind: str
    names: tuple[str, ...]
    indices: tuple[int, ...]

    @property
    def category(self) -> str:
        """The category of its keypoint trajectory: "closet" (a door) or "drawer"."""
        return PART_CATEGORY.get(self.kind, self.kind)


@torch.no_grad()
def object_parts(fitted: FittedModel, z: torch.Tensor) -> list[Part]:
    """The parts of code z (2 S + k,): a one-part model's one part; for several slots, those whose
    existence logit is positive, typed by their door and drawer logits (a drawer's axis points,
    its handle shut and fully open, left out)."""
    if fitted.num_slots == 1:
        names = fitted.keypoint_names
        return [Part(0, fitted.category, names, tuple(range(len(names))))]
    logits = fitted.model.slot_logits(z[None].to(fitted.codes))[0]
    parts = []
    for k in np.flatnonzero((logits[:, 0] > 0).cpu().numpy()):
        kind = PART_TYPES[int(logits[k, 1:].argmax())]
        names = PART_KEYPOINTS[kind]
        parts.append(Part(int(k), kind, tuple(names.values()),
                          tuple(int(k) * len(SLOT_KEYPOINTS) + SLOT_KEYPOINTS.index(n) for n in names)))
    return parts


def explored_at(fitted: FittedModel, name: str, z_obj: torch.Tensor, q: float) -> ExploredObject:
    """The object of z_obj (k,) at q in [0, 1]; for several slots, every part the keypoint head
    finds with all slots shut at q, the other slots shut."""
    S = fitted.num_slots
    if S == 1:
        return ExploredObject(name, z_obj, q)
    qs = np.zeros(S)
    qs[[p.slot for p in object_parts(fitted, ExploredObject(name, z_obj, qs).z)]] = q
    return ExploredObject(name, z_obj, qs)


@dataclass(frozen=True)
class View:
    """One camera: intrinsics, pose X_OC (4x4, OpenCV axes) in the object frame O and the point
    p_OT (3,) it looks at, m."""

    camera: PinholeCamera
    X_OC: np.ndarray
    p_OT: np.ndarray

    def pixel(self, p_O: np.ndarray) -> np.ndarray | None:
        """(u, v) of p_O (3,) with the top-left pixel's centre at (0, 0) (matplotlib's image
        coordinates); None behind the camera."""
        uv = project(CaptureFrame(image_path=None, X_OC=self.X_OC, camera=self.camera), p_O)
        return None if uv is None else uv - 0.5


def orbit_view(p_OT: np.ndarray, distance_m: float, azimuth_deg: float, size: int) -> View:
    """A square camera (vertical field of view FOV_Y_DEG) looking at p_OT (3,) from `distance_m`,
    at `azimuth_deg` around +z from the front (+x of O, positive towards +y) and
    VIEW_ELEVATION_DEG above the horizontal."""
    az, el = math.radians(azimuth_deg), math.radians(VIEW_ELEVATION_DEG)
    direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return View(PinholeCamera.from_fov(size, size, math.radians(FOV_Y_DEG)),
                look_at(p_OT + distance_m * direction, p_OT), np.asarray(p_OT, float))


def model_view(fitted: FittedModel, size: int = 128, azimuth_deg: float = VIEW_AZIMUTH_DEG,
               z_objs: torch.Tensor | None = None) -> View:
    """The camera of a model's figures: it looks at the centre of the surface of the objects
    z_objs (M, k) (default: the mean training code), their parts at q = 0 and 0.5, as the field
    renders them (the 2nd to 98th percentile box of their points), from the distance at which
    the box's bounding sphere spans VIEW_FILL of the image height. The points come from a
    low-resolution view PROBE_DISTANCE_M away, or further where the field's bounding sphere
    needs it to fit in."""
    half_fov = math.radians(FOV_Y_DEG) / 2.0
    probe_distance = max(PROBE_DISTANCE_M, fitted.model.config.bound_radius / math.sin(half_fov))
    probe = orbit_view(np.array(fitted.model.config.bound_center), probe_distance, azimuth_deg, 32)
    z_objs = fitted.z_obj_mean[None] if z_objs is None else z_objs
    points = np.concatenate([
        semantic_point_cloud(fitted.model, explored_at(fitted, "framed", z_obj, q).z, None,
                             [(probe.camera, probe.X_OC)])[0] for z_obj in z_objs for q in (0.0, 0.5)])
    if len(points) == 0:  # a field that renders nothing: the probe's view
        return orbit_view(probe.p_OT, probe_distance, azimuth_deg, size)
    lo, hi = np.percentile(points, [2.0, 98.0], axis=0)  # stray surface points left out
    centre = (lo + hi) / 2.0
    radius = float(np.linalg.norm(hi - lo)) / 2.0
    distance = radius / math.sin(VIEW_FILL * half_fov)
    return orbit_view(centre, distance, azimuth_deg, size)


def training_object(fitted: FittedModel, index: int, q: float) -> ExploredObject:
    """Training code `index` at q (`explored_at`)."""
    return explored_at(fitted, f"training object {index}", fitted.codes[index], q)


def fitted_object(fitted: FittedModel, capture: Path) -> ExploredObject:
    """The code the shipped fit defaults find for a capture set (`FitConfig()`; a model of several
    slots: `FurnitureFitConfig()` as `nfr-drake infer` fits furniture, `infer_parts`, every slot
    at the q of its z_art in the fitted code)."""
    cap = read_capture_set(capture)
    fitted.check_capture(cap)
    grid = np.linspace(0.0, 1.0, TRAJECTORY_POINTS)
    name, true_q = f"fitted {cap.root.name}", None if cap.gt is None else cap.gt["q"]
    if fitted.num_slots == 1:
        _, outcome = infer(fitted, cap, FitConfig(), grid)
        return ExploredObject(name, outcome.z[2:].detach(), outcome.q,
                              None if true_q is None else float(true_q))
    result, fit, _ = infer_parts(fitted, cap, FurnitureFitConfig(), grid)
    z_art, z_obj = split_z(fit.z.detach(), fitted.num_slots)
    return ExploredObject(name, z_obj, z_art_to_q(z_art.view(-1, ART_DIM)).double().cpu().numpy(),
                          None if true_q is None else np.asarray(true_q, float),
                          ", ".join(f"{p['index']} {p['type']}" for p in result.parts) or "none")


def interpolation_path(a: ExploredObject, b: ExploredObject, steps: int) -> list[ExploredObject]:
    """`steps` objects from a to b (ends included), named by their fraction t of the path; each
    slot's q moves from a's to b's."""
    t = np.linspace(0.0, 1.0, steps)
    z_obj, q = interpolate_codes(a.z_obj, a.q, b.z_obj, b.q, t)
    return [ExploredObject(f"t = {ti:.2f}", z, qi if np.ndim(qi) else float(qi))
            for ti, z, qi in zip(t, z_obj, q, strict=True)]


def render(fitted: FittedModel, obj: ExploredObject, view: View) -> SimulatedView:
    """The object rendered by the field from `view`, every slot at its q."""
    return render_view(fitted.model, obj.z, None, view.camera, view.X_OC)


def sampled_objects(fitted: FittedModel, count: int, seed: int) -> tuple[list[torch.Tensor], np.ndarray]:
    """`count` new z_obj (k,) drawn from the Gaussian of the training codes, and the distance of
    each to its nearest training code (count,)."""
    drawn = CodeGaussian.fit(fitted.codes).sample(count, np.random.default_rng(seed))
    z_objs = torch.as_tensor(drawn, dtype=fitted.codes.dtype)
    return list(z_objs), torch.cdist(z_objs, fitted.codes).min(-1).values.numpy()


def _rgb(image: np.ndarray) -> tuple[float, float, float]:
    return tuple(float(c) / 255.0 for c in image)


def _keypoint_kind(name: str) -> str:
    """The keypoint's name without its slot ("2/handle" -> "handle")."""
    return name.rsplit("/", 1)[-1]


def _figure(rows: list[list[np.ndarray]], row_names: list[str], titles: list[str], title: str,
            path: Path, category: str, keypoints: dict[int, list[dict[str, dict]]] | None = None) -> None:
    """A grid of uint8 RGB images with row names, column titles, a title and a legend of the
    classes (and keypoints). `keypoints[i][j]`, drawn over row i in column j: name -> {"now":
    (2,), "path": (N, 2)} pixels (`_keypoint_marks`; a name "SLOT/name" is one of a part slot,
    whose number is written by its handle)."""
    plt = pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n_rows, n_cols = len(rows), len(rows[0])
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(1.45 * n_cols + 0.6, 1.45 * n_rows + 1.1),
                             squeeze=False)
    for i, row in enumerate(rows):
        for j, image in enumerate(row):
            ax = axes[i, j]
            ax.imshow(image, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(titles[j], fontsize=8)
            if j == 0:
                ax.set_ylabel(row_names[i], fontsize=8)
            if keypoints is not None and i in keypoints:
                for name, marks in keypoints[i][j].items():
                    colour = KEYPOINT_COLOURS[_keypoint_kind(name)].rgba[:3]
                    ax.plot(marks["path"][:, 0], marks["path"][:, 1], "-", color=colour, lw=0.8)
                    ax.plot(*marks["now"], "o", color=colour, ms=3.5, mec="white", mew=0.5)
                    if "/" in name and _keypoint_kind(name) == "handle":
                        ax.annotate(name.split("/")[0], marks["now"], xytext=(2.5, 2.5), fontsize=6,
                                    textcoords="offset points", color="white", fontweight="bold")
                ax.set_xlim(-0.5, image.shape[1] - 0.5)
                ax.set_ylim(image.shape[0] - 0.5, -0.5)
    moving = {"closet": "door", "drawer": "drawer",
              "furniture": "door or drawer"}.get(category, "moving part")
    classes = [Patch(color=_rgb(SEMANTIC_PALETTE[c]), label=name)
               for c, name in ((1, "carcass"), (2, moving), (3, "handle"))]
    legend = {"fontsize": 7, "title_fontsize": 7, "frameon": False}
    fig.legend(handles=classes, loc="lower left" if keypoints else "lower center", ncol=3,
               title="segmentation classes", bbox_to_anchor=(0.05, 0) if keypoints else None, **legend)
    if keypoints is not None:
        names = dict.fromkeys(_keypoint_kind(n) for row in keypoints.values() for marks in row for n in marks)
        slots = any("/" in n for row in keypoints.values() for marks in row for n in marks)
        fig.legend(handles=[Line2D([], [], color=KEYPOINT_COLOURS[n].rgba[:3], marker="o", ms=4,
                                   label=n) for n in names],
                   loc="lower right", bbox_to_anchor=(0.95, 0), ncol=max(1, len(names)),
                   title="keypoints (dot: at the column's q; line: path over q in [0, 1]"
                         + ("; number: part slot" if slots else "") + ")", **legend)
    width, height = fig.get_size_inches()  # the title's lines above the grid, the legends' 0.4 in below
    lines = [wrapped for line in title.split("\n") for wrapped in textwrap.wrap(line, int(12 * width))]
    fig.text(0.5, 1 - 0.08 / height, "\n".join(lines), ha="center", va="top", fontsize=9)
    fig.tight_layout(rect=(0, 0.4 / height, 1, 1 - (0.12 + 0.16 * len(lines)) / height),
                     h_pad=0.3, w_pad=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _keypoint_marks(fitted: FittedModel, obj: ExploredObject, view: View,
                    swept: Collection[int] | None = None) -> dict[str, dict]:
    """Pixels of the keypoints of the object's parts (`object_parts`) at its q ("now") and, for
    the slots in `swept` (None: every part), along the slot's q over [0, 1] with the other slots
    held ("path", (N, 2); (0, 2) for the others). Keyed by name; "SLOT/name" for several slots."""
    grid = np.linspace(0.0, 1.0, TRAJECTORY_POINTS)
    now = keypoint_trajectory(fitted.model, obj.z, obj.qs[:1])[0]  # slot 0 at its own q: the code as it is
    marks = {}
    for part in object_parts(fitted, obj.z):
        path = (keypoint_trajectory(fitted.model, obj.z, grid, part.slot)[:, part.indices]
                if swept is None or part.slot in swept else np.zeros((0, len(part.indices), 3)))
        for i, (name, k) in enumerate(zip(part.names, part.indices, strict=True)):
            pixels = [p for p in map(view.pixel, path[:, i]) if p is not None]
            marks[f"{part.slot}/{name}" if fitted.num_slots > 1 else name] = {
                "now": view.pixel(now[k]), "path": np.array(pixels).reshape(-1, 2)}
    return {n: m for n, m in marks.items() if m["now"] is not None}


@dataclass(frozen=True)
class Strip:
    """Objects side by side in a strip figure: a name for its rows ("" for none), the objects
    (one per column) and the slots whose keypoint paths are drawn (`_keypoint_marks`' swept)."""

    name: str
    objects: list[ExploredObject]
    swept: Collection[int] | None = None


def strip_figure(fitted: FittedModel, strips: list[Strip], view: View, titles: list[str],
                 title: str, path: Path) -> list[list[SimulatedView]]:
    """Columns of objects; per strip, rows RGB (left out for several strips), segmentation and
    keypoints over the dimmed RGB (now: dots, over q: lines); returns the renders per strip and
    column."""
    renders = [[render(fitted, o, view) for o in tqdm(s.objects, desc=f"{path.stem} {s.name}".strip(),
                                                       unit="render")] for s in strips]
    kinds = ("RGB", "segmentation", "keypoints") if len(strips) == 1 else ("segmentation", "keypoints")
    rows, names, keypoints = [], [], {}
    for strip, views in zip(strips, renders, strict=True):
        images = {"RGB": [v.rgb for v in views], "segmentation": [colorize_labels(v.labels) for v in views],
                  "keypoints": [(v.rgb * 0.55 + 255 * 0.45).astype(np.uint8) for v in views]}
        keypoints[len(rows) + kinds.index("keypoints")] = [_keypoint_marks(fitted, o, view, strip.swept)
                                                           for o in strip.objects]
        rows += [images[kind] for kind in kinds]
        names += [f"{strip.name}\n{kind}" if strip.name else kind for kind in kinds]
    _figure(rows, names, titles, title, path, fitted.category, keypoints)
    return renders


def samples_figure(fitted: FittedModel, count: int, seed: int, q_values: tuple[float, ...],
                   size: int, path: Path) -> tuple[np.ndarray, float]:
    """New objects (columns) at each q of q_values (an RGB and a segmentation row per q; several
    slots: every part the keypoint head finds at q, `explored_at`), size x size pixels
    (`figure_view` of the samples); returns each sample's distance to its nearest training code
    (count,) and, for comparison, the median distance of a training code to its nearest other one."""
    z_objs, nearest = sampled_objects(fitted, count, seed)
    view = figure_view(fitted, size, [ExploredObject("sample", z, 0.0) for z in z_objs])
    rows, names = [], []
    with tqdm(total=count * len(q_values), desc=path.stem, unit="render") as bar:
        for q in q_values:
            views = []
            for i, z_obj in enumerate(z_objs):
                views.append(render(fitted, explored_at(fitted, f"sample {i}", z_obj, q), view))
                bar.update()
            rows += [[v.rgb for v in views], [colorize_labels(v.labels) for v in views]]
            names += [f"RGB, q = {q:.2f}", f"segmentation, q = {q:.2f}"]
    pairwise = torch.cdist(fitted.codes, fitted.codes)
    pairwise.fill_diagonal_(math.inf)
    typical = float(pairwise.min(-1).values.median())
    titles = [f"sample {i}\nnearest: {d:.2f}" for i, d in enumerate(nearest)]
    if fitted.num_slots > 1:
        titles = [f"{title}\n{_parts_count(fitted, explored_at(fitted, '', z, 0.0))}"
                  for title, z in zip(titles, z_objs, strict=True)]
    gaussian = "diagonal" if CodeGaussian.fit(fitted.codes).is_diagonal else "full"
    parts = "; every part the keypoint head finds at the row's q" if fitted.num_slots > 1 else ""
    _figure(rows, names, titles,
            f"{fitted.category}: new objects, z_obj ~ Gaussian of the {len(fitted.codes)} training codes "
            f"({gaussian} covariance){parts}\ncolumn titles: distance to the nearest training code "
            f"(a training code's to its nearest other: median {typical:.2f})",
            path, fitted.category)
    return nearest, typical


def object_html(fitted: FittedModel, obj: ExploredObject, view: View, path: Path,
                cloud_views: int = 5, cloud_size: int = 96) -> int:
    """Write the Meshcat page of `obj` (its semantic point cloud at its q, every slot at its own,
    coloured by class, and the keypoint trajectories over q in [0, 1] of each of its parts,
    `object_parts`: under "object/keypoints", or per part slot K "object/keypoints/partK" swept
    with the other slots held); returns the number of points."""
    from pydrake.geometry import Meshcat, Rgba
    from pydrake.perception import BaseField, Fields, PointCloud

    distance = float(np.linalg.norm(view.X_OC[:3, 3] - view.p_OT))
    around = [orbit_view(view.p_OT, distance, az, cloud_size)
              for az in np.linspace(-60.0, 60.0, cloud_views)]
    points, classes = semantic_point_cloud(fitted.model, obj.z, None, [(v.camera, v.X_OC) for v in around])
    cloud = PointCloud(len(points), Fields(BaseField.kXYZs | BaseField.kRGBs))
    cloud.mutable_xyzs()[:] = points.T
    # Meshcat's viewer treats vertex colours as linear and encodes them to sRGB: pass the
    # palette's linear values so that the page shows the palette itself.
    linear = np.round(255.0 * (SEMANTIC_PALETTE / 255.0) ** 2.2).astype(np.uint8)
    cloud.mutable_rgbs()[:] = linear[classes].T
    grid = np.linspace(0.0, 1.0, TRAJECTORY_POINTS)
    meshcat = Meshcat()
    meshcat.SetObject("object/point_cloud", cloud, 0.01, Rgba(1.0, 1.0, 1.0, 1.0))
    for part in object_parts(fitted, obj.z):
        p_OK = keypoint_trajectory(fitted.model, obj.z, grid, part.slot)[:, part.indices]
        trajectory = KeypointTrajectory(part.category, grid, part.names, p_OK, float(obj.qs[part.slot]))
        draw_keypoint_trajectory(meshcat, trajectory, "object/keypoints" if fitted.num_slots == 1
                                 else f"object/keypoints/part{part.slot}")
    frame_camera(meshcat, view.p_OT, view.X_OC[:3, 3])
    write_replay(meshcat, path)
    return len(points)


def _check_writable(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".explore_write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as err:
        raise NfrDrakeError(f"{out}: cannot write there ({err.strerror or err})") from None


def _parts_count(fitted: FittedModel, obj: ExploredObject) -> str:
    """How many parts of each kind the keypoint head finds in an object, e.g. "1 door, 2 drawers"."""
    kinds = [p.kind for p in object_parts(fitted, obj.z)]
    return ", ".join(f"{kinds.count(k)} {k}{'s' if kinds.count(k) > 1 else ''}"
                     for k in dict.fromkeys(kinds)) or "no parts"


def _parts_text(fitted: FittedModel, obj: ExploredObject) -> str:
    """The parts the keypoint head finds in an object, e.g. "0 drawer, 1 door" ("none")."""
    return ", ".join(f"{p.slot} {p.kind}" for p in object_parts(fitted, obj.z)) or "none"


def figure_view(fitted: FittedModel, size: int, objects: list[ExploredObject]) -> View:
    """The camera (size x size pixels) of a figure of `objects`: a one-part model's one camera,
    framing the mean object (`model_view`); for several slots one framing these objects: pieces
    of furniture range from a low table to a wardrobe, which the mean code's framing would cut off
    or show tiny."""
    if fitted.num_slots == 1:
        return model_view(fitted, size)
    return model_view(fitted, size, z_objs=torch.stack([o.z_obj for o in objects]))


def articulation_strips(fitted: FittedModel, obj: ExploredObject, steps: int,
                        part: int | None = None) -> list[Strip]:
    """The object at `steps` articulations q over [0, 1]: a one-part model's one strip; for several
    slots one strip per part the keypoint head finds (or slot `part` alone), that slot swept, the
    others held at the object's q."""
    q_values = np.linspace(0.0, 1.0, steps)
    if fitted.num_slots == 1:
        return [Strip("", [obj.with_slot(0, float(q)) for q in q_values], {0})]
    kinds = {p.slot: p.kind for p in object_parts(fitted, obj.z)}
    slots = [part] if part is not None else list(kinds) or [0]
    return [Strip(f"part {k}, {kinds.get(k, 'not found')}",
                  [obj.with_slot(k, float(q)) for q in q_values], {k}) for k in slots]


def explore_command(
    model: Annotated[Path, tyro.conf.Positional],
    out: Path = Path("out/explore"),
    capture: Annotated[tuple[Path, ...], tyro.conf.UseAppendAction] = (),
    seed: int = 0,
    steps: int = 7,
    q_ends: tuple[float, float] = (0.0, 0.7),
    samples: int = 6,
    sample_q: tuple[float, ...] = (0.0, 0.5, 1.0),
    part: int | None = None,
    size: int = 128,
    threads: int | None = None,
) -> None:
    """Write the figures of what MODEL has learned into OUT: interpolation.png, articulations.png,
    samples.png and object.html.

    Args:
        model: model folder (model.safetensors + config.json); one part (closet, drawer) or several
            part slots (furniture).
        out: folder for the figures.
        capture: up to two capture sets (repeat the option); their fitted codes are the ends of the
            interpolation, the first is the object of articulations.png and object.html. Missing
            ends are training codes: one chosen by the seed, the other the farthest from the first
            end in z_obj.
        seed: chooses the training object and the sampled codes.
        steps: columns of the interpolation and of the articulation sweep.
        q_ends: articulations of training-code ends (first, second), in [0, 1]; furniture: of every
            part the keypoint head finds in the code.
        samples: new objects drawn from the Gaussian of the training codes.
        sample_q: articulations at which the new objects are rendered.
        part: a model of several part slots: the one slot swept in articulations.png (default:
            every part the keypoint head finds in the first object, one strip each).
        size: rendered image size, pixels (square).
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    if len(capture) > 2:
        raise ConfigError(f"--capture: at most two capture sets, got {len(capture)}")
    if steps < 2 or samples < 1 or size < 8 or not sample_q:
        raise ConfigError("--steps must be >= 2, --samples >= 1, --size >= 8, --sample-q not empty")
    if not all(0.0 <= q <= 1.0 for q in (*q_ends, *sample_q)):
        raise ConfigError("--q-ends and --sample-q must lie in [0, 1]")
    set_torch_threads(threads)
    fitted = FittedModel(model)
    slots = fitted.num_slots
    if part is not None and slots == 1:
        raise ConfigError(f"--part is for models of several part slots (furniture); {model} has one")
    if part is not None and not 0 <= part < slots:
        raise ConfigError(f"--part {part}: {model} has {slots} part slots, 0 to {slots - 1}")
    for c in capture:
        fitted.check_capture(read_capture_set(c))
    _check_writable(out)

    ends = [fitted_object(fitted, c) for c in tqdm(capture, desc="fit", unit="capture", disable=not capture)]
    if not ends:
        ends.append(training_object(fitted, int(np.random.default_rng(seed).integers(len(fitted.codes))),
                                    q_ends[0]))
    if len(ends) == 1:
        ends.append(training_object(fitted, farthest_code(fitted.codes, ends[0].z_obj), q_ends[1]))
    a, b = ends
    cat = fitted.category
    path = interpolation_path(a, b, steps)
    each = ", every part slot at its own q" if slots > 1 else ""
    strip_figure(fitted, [Strip("", path)], figure_view(fitted, size, [a, b]),
                 [f"{o.name}\nq = {o.q:.2f}" if slots == 1 else o.name for o in path],
                 f"{cat}: interpolation of z_obj and z_art{each}; "
                 f"left: {a.describe()}, right: {b.describe()}",
                 out / "interpolation.png")
    strips = articulation_strips(fitted, a, steps, part)
    held = "one part at a time, the others held; " if slots > 1 else ""
    view_a = figure_view(fitted, size, [a])
    strip_figure(fitted, strips, view_a, [f"q = {q:.2f}" for q in np.linspace(0.0, 1.0, steps)],
                 f"{cat}: new articulations of {a.describe()}; {held}lines: keypoint paths over q",
                 out / "articulations.png")
    nearest, typical = samples_figure(fitted, samples, seed, sample_q, size, out / "samples.png")
    points = object_html(fitted, a, view_a, out / "object.html")
    print(f"interpolation: {a.describe()} -> {b.describe()}, "
          f"z_obj distance {float((a.z_obj - b.z_obj).norm()):.2f}")
    if slots > 1:
        for end in (a, b):
            listed = "" if end.fit_parts is None else f" (its fit lists {end.fit_parts})"
            print(f"{end.name}: the keypoint head finds parts {_parts_text(fitted, end)}{listed}")
        print(f"articulations: {'; '.join(s.name for s in strips)}: swept one at a time")
    print(f"samples: distance to the nearest training code {', '.join(f'{d:.2f}' for d in nearest)} "
          f"(a training code's to its nearest other: median {typical:.2f})")
    print(f"wrote {out / 'interpolation.png'}, {out / 'articulations.png'}, {out / 'samples.png'}, "
          f"{out / 'object.html'} ({points} points)")
