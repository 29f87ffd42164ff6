"""Forward simulation of a fitted object: sweep z_art over q with z_obj fixed.

For any articulation q and any camera, the fitted code gives keypoints (the keypoint head),
RGB renders, segmentations and surface points (the field and the raymarcher). All positions are in
the object frame O of the capture, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame
from nfr_drake.inference.fit import frame_ray_directions
from nfr_drake.nfr.latent import ART_DIM, q_to_z_art, split_z
from nfr_drake.nfr.model import NFRModel
from nfr_drake.nfr.rays import Rays


def code_at(z: torch.Tensor, q: float | np.ndarray, num_slots: int = 1, slot: int = 0) -> torch.Tensor:
    """Codes (N, 2 S + k) of z (2 S + k,) with slot `slot`'s articulation at q (N,) (one code for a
    float), z's object part and its other slots' articulations held."""
    qs = torch.as_tensor(np.atleast_1d(q), dtype=z.dtype, device=z.device)
    z_art, z_obj = split_z(z, num_slots)
    art = z_art.view(num_slots, ART_DIM).expand(len(qs), num_slots, ART_DIM).clone()
    art[:, slot] = q_to_z_art(qs)
    return torch.cat([art.flatten(1), z_obj.expand(len(qs), -1)], dim=-1)


@torch.no_grad()
def keypoint_trajectory(model: NFRModel, z: torch.Tensor, q_grid: np.ndarray, slot: int = 0) -> np.ndarray:
    """Keypoints (N, K, 3) in O (all slots') for each q of q_grid (N,) of slot `slot`, z_obj and
    the other slots' articulations fixed."""
    return model.keypoints(code_at(z, q_grid, model.config.num_slots, slot)).double().cpu().numpy()


@dataclass
class SimulatedView:
    """rgb uint8 (H, W, 3); labels uint8 (H, W) argmax class; points float32 (H, W, 3) surface
    points in O; depth float32 (H, W) distance along each ray, m."""

    rgb: np.ndarray
    labels: np.ndarray
    points: np.ndarray
    depth: np.ndarray


@torch.no_grad()
def render_view(model: NFRModel, z: torch.Tensor, q: float | None, camera: PinholeCamera,
                X_OC: np.ndarray, chunk: int = 8192) -> SimulatedView:
    """Render the fitted object at articulation q from a camera at X_OC (4x4, OpenCV axes); q
    None: the code z as it is (a code of several part slots, each at its own articulation)."""
    frame = CaptureFrame(image_path=None, X_OC=np.asarray(X_OC, float), camera=camera)
    dtype = next(model.parameters()).dtype
    device = next(model.parameters()).device
    directions = torch.from_numpy(frame_ray_directions(frame)).to(dtype=dtype, device=device)
    origin = torch.as_tensor(X_OC[:3, 3], dtype=dtype, device=device)
    z = z.to(dtype=dtype, device=device)
    code = z[None] if q is None else code_at(z, q)
    rgb, logits, points, depth = [], [], [], []
    for s in range(0, len(directions), chunk):
        d = directions[s:s + chunk][None]
        out = model.render(code, Rays(origin.expand_as(d), d))
        rgb.append(out.rgb[0])
        logits.append(out.logits[0])
        points.append(out.points[0])
        depth.append(out.depth[0])
    H, W = camera.height, camera.width
    rgb = torch.cat(rgb).clamp(0, 1).mul(255).round().to(torch.uint8).cpu().numpy()
    return SimulatedView(rgb=rgb.reshape(H, W, 3),
                         labels=torch.cat(logits).argmax(-1).to(torch.uint8).cpu().numpy()
                         .reshape(H, W),
                         points=torch.cat(points).float().cpu().numpy().reshape(H, W, 3),
                         depth=torch.cat(depth).float().cpu().numpy().reshape(H, W))


def semantic_point_cloud(model: NFRModel, z: torch.Tensor, q: float | None,
                         views: list[tuple[PinholeCamera, np.ndarray]]
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Surface points (N, 3) in O and their classes (N,) of the object at q (None: the code z as
    it is, `render_view`), seen from `views` (camera, X_OC); background pixels are dropped."""
    points, classes = [], []
    for camera, X_OC in views:
        view = render_view(model, z, q, camera, X_OC)
        mask = view.labels > 0
        points.append(view.points[mask])
        classes.append(view.labels[mask])
    return np.concatenate(points), np.concatenate(classes)


def handle_path_from_segmentation(model: NFRModel, z: torch.Tensor, q_grid: np.ndarray,
                                  views: list[tuple[PinholeCamera, np.ndarray]],
                                  handle_class: int = 3, size: int = 48) -> np.ndarray:
    """Handle positions (N, 3) in O read from the field's own geometry along q_grid (N,).

    At each q the object is rendered from `views` (camera, X_OC), downscaled to `size` pixels
    high; the handle is the centroid of the surface points labelled `handle_class`. Where no view
    sees the handle, the position is interpolated over q from the nearest ones that do; NaN when
    no q sees it at all.
    """
    small = [(cam.scaled(max(1, round(cam.width * size / cam.height)), size), X) for cam, X in views]
    path = np.full((len(q_grid), 3), np.nan)
    for i, q in enumerate(q_grid):
        points, classes = semantic_point_cloud(model, z, float(q), small)
        handle = points[classes == handle_class]
        if len(handle):
            path[i] = handle.mean(0)
    seen = ~np.isnan(path[:, 0])
    if seen.any() and not seen.all():
        for j in range(3):
            path[~seen, j] = np.interp(np.asarray(q_grid)[~seen], np.asarray(q_grid)[seen],
                                       path[seen, j])
    return path


def rotation_axis_from_path(path: np.ndarray) -> np.ndarray:
    """Centre (x, y) of the circle that best fits a path's horizontal positions (N, 3), in the
    least-squares sense (Kasa fit): a vertical hinge axis from a handle's arc. Shape (2,)."""
    x, y = path[:, 0], path[:, 1]
    A = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
    (cx, cy, _), *_ = np.linalg.lstsq(A, x**2 + y**2, rcond=None)
    return np.array([cx, cy])


def geometric_keypoints(model: NFRModel, z: torch.Tensor, q: float, q_grid: np.ndarray,
                        names: tuple[str, ...], views: list[tuple[PinholeCamera, np.ndarray]],
                        max_views: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints read from the fitted field's geometry where it shows them, the head elsewhere.

    The handle comes from the rendered segmentation (`handle_path_from_segmentation`) at q and
    along q_grid; for a door (keypoints `hinge_top`, `hinge_bottom`) the hinge axis is the centre
    of the simulated handle arc, at the heights the keypoint head predicts. Other keypoints
    (`goal`) are the head's. Returns keypoints at q (K, 3) and along q_grid (N, K, 3).
    """
    head_now = keypoint_trajectory(model, z, np.array([q]))[0]
    head_path = keypoint_trajectory(model, z, q_grid)
    picks = np.unique(np.linspace(0, len(views) - 1, min(max_views, len(views))).round().astype(int))
    chosen = [views[i] for i in picks]
    h = names.index("handle")
    now, path = head_now.copy(), head_path.copy()
    handle_now = handle_path_from_segmentation(model, z, np.array([q]), chosen)[0]
    handle_path = handle_path_from_segmentation(model, z, q_grid, chosen)
    if not np.isnan(handle_now).any():
        now[h] = handle_now
    if not np.isnan(handle_path).any():
        path[:, h] = handle_path
        if {"hinge_top", "hinge_bottom"} <= set(names):
            axis = rotation_axis_from_path(handle_path)
            for name in ("hinge_top", "hinge_bottom"):
                k = names.index(name)
                now[k, :2] = axis
                path[:, k, :2] = axis
    return now, path
