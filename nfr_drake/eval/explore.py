"""`nfr-drake explore`: what a neural field has learned (the paper's generative evaluation).

Four products, from the training codes of a model folder or from codes fitted to capture sets:
- `interpolation.png`: renders, segmentations and keypoints along the path between two objects,
  z_obj on a straight line and z_art on the unit circle (paper, Fig. "Interpolation of latent
  codes across articulation code and object code");
- `articulations.png`: one object at new articulations q in [0, 1] (forward simulation);
- `samples.png`: new objects, z_obj drawn from a Gaussian fitted to the training codes;
- `object.html`: a self-contained Meshcat page of one object: its labelled point cloud at its q
  and its keypoint trajectories over q, to turn around in a browser (offline).

All renders come from one camera per model, framing the mean object (`model_view`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
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
from nfr_drake.data.visualize import SEMANTIC_PALETTE, colorize_labels, pyplot
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.forward import (
    SimulatedView,
    keypoint_trajectory,
    render_view,
    semantic_point_cloud,
)
from nfr_drake.inference.infer import FittedModel, infer
from nfr_drake.inference.latent_space import CodeGaussian, farthest_code, interpolate_codes
from nfr_drake.nfr.latent import q_to_z_art
from nfr_drake.perception.handle_triangulation import project
from nfr_drake.systems.replay import KEYPOINT_COLOURS, draw_keypoint_trajectory, frame_camera, write_replay
from nfr_drake.world.keypoints import KeypointTrajectory

VIEW_AZIMUTH_DEG = 30.0
VIEW_ELEVATION_DEG = 20.0
FOV_Y_DEG = 50.0
VIEW_FILL = 0.85
"""Share of the image height that the mean object's bounding sphere spans in the figures."""
PROBE_DISTANCE_M = 2.2
"""Distance of the low-resolution view that measures the mean object (`model_view`)."""
TRAJECTORY_POINTS = 21
"""Points of the q grid over [0, 1] of keypoint trajectories."""


@dataclass(frozen=True)
class ExploredObject:
    """An object in the model's code space: its name, z_obj (k,), articulation q in [0, 1] and,
    for a fitted capture with ground truth, the capture's true q."""

    name: str
    z_obj: torch.Tensor
    q: float
    true_q: float | None = None

    def describe(self) -> str:
        """Name and q, e.g. "fitted closet_000 (q 0.11, true 0.10)"."""
        truth = "" if self.true_q is None else f", true {self.true_q:.2f}"
        return f"{self.name} (q {self.q:.2f}{truth})"

    @property
    def z(self) -> torch.Tensor:
        """The code (2 + k,): z_art = (cos(pi q), sin(pi q)), then z_obj."""
        return torch.cat([q_to_z_art(self.z_obj.new_tensor(self.q)), self.z_obj])


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


def model_view(fitted: FittedModel, size: int = 128, azimuth_deg: float = VIEW_AZIMUTH_DEG) -> View:
    """The camera of a model's figures: it looks at the centre of the mean object's surface
    (z_obj the mean training code, at q = 0 and 0.5, as the field renders it; the 2nd to 98th
    percentile box of its points) from the distance at which the box's bounding sphere spans
    VIEW_FILL of the image height."""
    mean = fitted.z_obj_mean
    probe = orbit_view(np.array(fitted.model.config.bound_center), PROBE_DISTANCE_M, azimuth_deg, 32)
    points = np.concatenate([
        semantic_point_cloud(fitted.model, ExploredObject("mean", mean, q).z, q,
                             [(probe.camera, probe.X_OC)])[0] for q in (0.0, 0.5)])
    if len(points) == 0:  # a field that renders nothing: the probe's view
        return orbit_view(probe.p_OT, PROBE_DISTANCE_M, azimuth_deg, size)
    lo, hi = np.percentile(points, [2.0, 98.0], axis=0)  # stray surface points left out
    centre = (lo + hi) / 2.0
    radius = float(np.linalg.norm(hi - lo)) / 2.0
    distance = radius / math.sin(VIEW_FILL * math.radians(FOV_Y_DEG) / 2.0)
    return orbit_view(centre, distance, azimuth_deg, size)


def training_object(fitted: FittedModel, index: int, q: float) -> ExploredObject:
    return ExploredObject(f"training object {index}", fitted.codes[index], q)


def fitted_object(fitted: FittedModel, capture: Path) -> ExploredObject:
    """The code the shipped fit defaults (`FitConfig()`) find for a capture set."""
    cap = read_capture_set(capture)
    fitted.check_capture(cap)
    _, outcome = infer(fitted, cap, FitConfig(), np.linspace(0.0, 1.0, TRAJECTORY_POINTS))
    return ExploredObject(f"fitted {cap.root.name}", outcome.z[2:].detach(), outcome.q,
                          None if cap.gt is None else float(cap.gt["q"]))


def interpolation_path(a: ExploredObject, b: ExploredObject, steps: int) -> list[ExploredObject]:
    """`steps` objects from a to b (ends included), named by their fraction t of the path."""
    t = np.linspace(0.0, 1.0, steps)
    z_obj, q = interpolate_codes(a.z_obj, a.q, b.z_obj, b.q, t)
    return [ExploredObject(f"t = {ti:.2f}", z, float(qi)) for ti, z, qi in zip(t, z_obj, q, strict=True)]


def render(fitted: FittedModel, obj: ExploredObject, view: View) -> SimulatedView:
    return render_view(fitted.model, obj.z, obj.q, view.camera, view.X_OC)


def sampled_objects(fitted: FittedModel, count: int, seed: int) -> tuple[list[torch.Tensor], np.ndarray]:
    """`count` new z_obj (k,) drawn from the Gaussian of the training codes, and the distance of
    each to its nearest training code (count,)."""
    drawn = CodeGaussian.fit(fitted.codes).sample(count, np.random.default_rng(seed))
    z_objs = torch.as_tensor(drawn, dtype=fitted.codes.dtype)
    return list(z_objs), torch.cdist(z_objs, fitted.codes).min(-1).values.numpy()


def _rgb(image: np.ndarray) -> tuple[float, float, float]:
    return tuple(float(c) / 255.0 for c in image)


def _figure(rows: list[list[np.ndarray]], row_names: list[str], titles: list[str], title: str,
            path: Path, category: str, keypoints: list[list[dict[str, np.ndarray]]] | None = None,
            keypoint_row: int | None = None) -> None:
    """A grid of uint8 RGB images with row names, column titles, a title and a legend of the
    classes (and keypoints). `keypoints[j]` of column j: name -> {"now": (2,), "path": (N, 2)}
    pixels, drawn over row `keypoint_row`."""
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
            if keypoints is not None and i == keypoint_row:
                for name, marks in keypoints[j].items():
                    colour = KEYPOINT_COLOURS[name].rgba[:3]
                    ax.plot(marks["path"][:, 0], marks["path"][:, 1], "-", color=colour, lw=0.8)
                    ax.plot(*marks["now"], "o", color=colour, ms=3.5, mec="white", mew=0.5)
                ax.set_xlim(-0.5, image.shape[1] - 0.5)
                ax.set_ylim(image.shape[0] - 0.5, -0.5)
    moving = {"closet": "door", "drawer": "drawer"}.get(category, "moving part")
    classes = [Patch(color=_rgb(SEMANTIC_PALETTE[c]), label=name)
               for c, name in ((1, "carcass"), (2, moving), (3, "handle"))]
    legend = {"fontsize": 7, "title_fontsize": 7, "frameon": False}
    fig.legend(handles=classes, loc="lower left" if keypoints else "lower center", ncol=3,
               title="segmentation classes", bbox_to_anchor=(0.05, 0) if keypoints else None, **legend)
    if keypoints is not None:
        names = dict.fromkeys(n for marks in keypoints for n in marks)
        fig.legend(handles=[Line2D([], [], color=KEYPOINT_COLOURS[n].rgba[:3], marker="o", ms=4,
                                   label=n) for n in names],
                   loc="lower right", bbox_to_anchor=(0.95, 0), ncol=len(names),
                   title="keypoints (dot: at the column's q; line: path over q in [0, 1])", **legend)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1), h_pad=0.3, w_pad=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _keypoint_marks(fitted: FittedModel, obj: ExploredObject, view: View) -> dict[str, dict]:
    """Pixels of the object's keypoints at its q ("now") and along q in [0, 1] ("path")."""
    grid = np.linspace(0.0, 1.0, TRAJECTORY_POINTS)
    path = keypoint_trajectory(fitted.model, obj.z, grid)
    now = keypoint_trajectory(fitted.model, obj.z, np.array([obj.q]))[0]
    marks = {}
    for k, name in enumerate(fitted.keypoint_names):
        pixels = [view.pixel(p) for p in path[:, k]]
        marks[name] = {"now": view.pixel(now[k]),
                       "path": np.array([p for p in pixels if p is not None]).reshape(-1, 2)}
    return {n: m for n, m in marks.items() if m["now"] is not None}


def strip_figure(fitted: FittedModel, objects: list[ExploredObject], view: View, titles: list[str],
                 title: str, path: Path) -> list[SimulatedView]:
    """Columns of objects; rows RGB, segmentation and keypoints (now: dots, over q: lines)."""
    views = [render(fitted, o, view) for o in tqdm(objects, desc=path.stem, unit="render")]
    marks = [_keypoint_marks(fitted, o, view) for o in objects]
    dim = [(v.rgb * 0.55 + 255 * 0.45).astype(np.uint8) for v in views]
    _figure([[v.rgb for v in views], [colorize_labels(v.labels) for v in views], dim],
            ["RGB", "segmentation", "keypoints"], titles, title, path, fitted.category, marks, 2)
    return views


def samples_figure(fitted: FittedModel, count: int, seed: int, q_values: tuple[float, ...],
                   view: View, path: Path) -> tuple[np.ndarray, float]:
    """New objects (columns) at each q of q_values (an RGB and a segmentation row per q);
    returns each sample's distance to its nearest training code (count,) and, for comparison,
    the median distance of a training code to its nearest other one."""
    z_objs, nearest = sampled_objects(fitted, count, seed)
    rows, names = [], []
    with tqdm(total=count * len(q_values), desc=path.stem, unit="render") as bar:
        for q in q_values:
            views = []
            for i, z_obj in enumerate(z_objs):
                views.append(render(fitted, ExploredObject(f"sample {i}", z_obj, q), view))
                bar.update()
            rows += [[v.rgb for v in views], [colorize_labels(v.labels) for v in views]]
            names += [f"RGB, q = {q:.2f}", f"segmentation, q = {q:.2f}"]
    pairwise = torch.cdist(fitted.codes, fitted.codes)
    pairwise.fill_diagonal_(math.inf)
    typical = float(pairwise.min(-1).values.median())
    titles = [f"sample {i}\nnearest: {d:.2f}" for i, d in enumerate(nearest)]
    gaussian = "diagonal" if CodeGaussian.fit(fitted.codes).is_diagonal else "full"
    _figure(rows, names, titles,
            f"{fitted.category}: new objects, z_obj ~ Gaussian of the {len(fitted.codes)} training codes "
            f"({gaussian} covariance)\ncolumn titles: distance to the nearest training code "
            f"(a training code's to its nearest other: median {typical:.2f})",
            path, fitted.category)
    return nearest, typical


def object_html(fitted: FittedModel, obj: ExploredObject, view: View, path: Path,
                cloud_views: int = 5, cloud_size: int = 96) -> int:
    """Write the Meshcat page of `obj` (its semantic point cloud at its q, coloured by class, and
    its keypoint trajectories over q in [0, 1]); returns the number of points."""
    from pydrake.geometry import Meshcat, Rgba
    from pydrake.perception import BaseField, Fields, PointCloud

    distance = float(np.linalg.norm(view.X_OC[:3, 3] - view.p_OT))
    around = [orbit_view(view.p_OT, distance, az, cloud_size)
              for az in np.linspace(-60.0, 60.0, cloud_views)]
    points, classes = semantic_point_cloud(fitted.model, obj.z, obj.q,
                                           [(v.camera, v.X_OC) for v in around])
    cloud = PointCloud(len(points), Fields(BaseField.kXYZs | BaseField.kRGBs))
    cloud.mutable_xyzs()[:] = points.T
    # Meshcat's viewer treats vertex colours as linear and encodes them to sRGB: pass the
    # palette's linear values so that the page shows the palette itself.
    linear = np.round(255.0 * (SEMANTIC_PALETTE / 255.0) ** 2.2).astype(np.uint8)
    cloud.mutable_rgbs()[:] = linear[classes].T
    grid = np.linspace(0.0, 1.0, TRAJECTORY_POINTS)
    trajectory = KeypointTrajectory(fitted.category, grid, fitted.keypoint_names,
                                    keypoint_trajectory(fitted.model, obj.z, grid), obj.q)
    meshcat = Meshcat()
    meshcat.SetObject("object/point_cloud", cloud, 0.01, Rgba(1.0, 1.0, 1.0, 1.0))
    draw_keypoint_trajectory(meshcat, trajectory, "object/keypoints")
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


def explore_command(
    model: Annotated[Path, tyro.conf.Positional],
    out: Path = Path("out/explore"),
    capture: Annotated[tuple[Path, ...], tyro.conf.UseAppendAction] = (),
    seed: int = 0,
    steps: int = 7,
    q_ends: tuple[float, float] = (0.0, 0.7),
    samples: int = 6,
    sample_q: tuple[float, ...] = (0.0, 0.5, 1.0),
    size: int = 128,
    threads: int | None = None,
) -> None:
    """Write the figures of what MODEL has learned into OUT: interpolation.png, articulations.png,
    samples.png and object.html.

    Args:
        model: model folder (model.safetensors + config.json).
        out: folder for the figures.
        capture: up to two capture sets (repeat the option); their fitted codes are the ends of the
            interpolation, the first is the object of articulations.png and object.html. Missing
            ends are training codes: one chosen by the seed, the other the farthest from the first
            end in z_obj.
        seed: chooses the training object and the sampled codes.
        steps: columns of the interpolation and of the articulation sweep.
        q_ends: articulations of training-code ends (first, second), in [0, 1].
        samples: new objects drawn from the Gaussian of the training codes.
        sample_q: articulations at which the new objects are rendered.
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
    slots = fitted.model.config.num_slots
    if slots > 1:
        raise ConfigError(f"{model}: a model of {slots} part slots ({fitted.category}); explore draws the "
                          "one-part models (models/closet, models/drawer); for a piece of furniture, "
                          "`nfr-drake infer CAPTURE --model MODEL` lists every part with its keypoints "
                          "and paths, and `nfr-drake eval --category furniture` draws them")
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
    view = model_view(fitted, size)
    cat = fitted.category
    path = interpolation_path(a, b, steps)
    strip_figure(fitted, path, view, [f"{o.name}\nq = {o.q:.2f}" for o in path],
                 f"{cat}: interpolation of z_obj and z_art; left: {a.describe()}, right: {b.describe()}",
                 out / "interpolation.png")
    sweep = [ExploredObject(a.name, a.z_obj, float(q)) for q in np.linspace(0.0, 1.0, steps)]
    strip_figure(fitted, sweep, view, [f"q = {o.q:.2f}" for o in sweep],
                 f"{cat}: new articulations of {a.describe()}; "
                 "lines: keypoint paths over q", out / "articulations.png")
    nearest, typical = samples_figure(fitted, samples, seed, sample_q, view, out / "samples.png")
    points = object_html(fitted, a, view, out / "object.html")
    print(f"interpolation: {a.describe()} -> {b.describe()}, "
          f"z_obj distance {float((a.z_obj - b.z_obj).norm()):.2f}")
    print(f"samples: distance to the nearest training code {', '.join(f'{d:.2f}' for d in nearest)} "
          f"(a training code's to its nearest other: median {typical:.2f})")
    print(f"wrote {out / 'interpolation.png'}, {out / 'articulations.png'}, {out / 'samples.png'}, "
          f"{out / 'object.html'} ({points} points)")
