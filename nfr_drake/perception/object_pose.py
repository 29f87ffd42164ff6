"""The object's pose on the floor from its masks in posed views: a visual hull, its footprint, X_WO.

World frame W: metric, z up, the floor at z = 0 (a ChArUco board lying on the floor, a room
capture). Object frame O (docs/CONVENTIONS.md): origin on the floor under the centre of the
carcass footprint, +x out of the front, +z up; so X_WO is (x, y, yaw) with z = 0.

1. **Hull**: voxel centres on a floor-aligned grid are projected into every view; a voxel is kept
   when the views whose image holds it (at least `min_views`) all see it inside the object's mask,
   all but `max_misses` of them (a bad mask, an occluder). Views that do not hold a voxel (an image
   edge cutting the object) say nothing about it. A coarse pass over the cameras' surroundings
   finds the object (the connected part most views see on the mask); a fine pass over that part's
   bounds measures it.
2. **Height**: the top of the hull (the highest slice with at least half the typical slice area).
3. **Footprint**: the columns occupied just under the top (`top_band_m`): cameras look at the
   object from its front and from above, so the hull's back is bounded well only near its top, and
   a door or drawer opened forward lies lower or is thin; a morphological opening
   (`opening_m`) removes thin panels (an open door) and the handles.
4. **Yaw**: the minimum-area rectangle of the footprint; +x of O is the rectangle's side facing the
   cameras' mean position (cameras see the front). Fronts are mounted on the carcass, so the
   carcass footprint is the rectangle less `front_thickness_m` at the front.
5. **Box**: a floor box fitted to the masks from that start (`fit_box`).

The masks are the object's visible pixels (a photo of the object alone, the segmenter's
`object_mask`), fronts included; or, with `amodal=True`, the carcass's amodal masks (its body
alone as if nothing hid it, no fronts: `data.amodal`, `Segmenter.carcass_amodal`): the box is then
the carcass itself, and neither clutter that hides part of it nor an open front in front of it
moves the box.

Pure numpy and OpenCV; no Drake.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from nfr_drake.data.camera import PinholeCamera, project_points
from nfr_drake.errors import NfrDrakeError


class ObjectPoseError(NfrDrakeError):
    """The masks and camera poses give no object on the floor."""


@dataclass(frozen=True)
class HullConfig:
    """Options of the hull and footprint (lengths in m)."""

    voxel_m: float = 0.02
    """Voxel size of the fine pass."""
    coarse_voxel_m: float = 0.08
    """Voxel size of the coarse pass that finds the object."""
    search_margin_m: float = 1.5
    """The coarse pass covers the cameras' xy bounds widened by this, from the floor to the
    highest camera."""
    mask_threshold: float = 0.5
    """A pixel is on the object when its mask value exceeds this."""
    min_views: int = 3
    """Views whose image must hold a voxel for it to be kept: at least this many, and at least
    half of all views (a region that only a few close, cut views hold is not the object)."""
    max_misses: int = 1
    """Views holding a voxel that may see it outside the mask (one bad mask, an occluder)."""
    top_band_m: tuple[float, float] = (0.015, 0.06)
    """Slices between these depths under the hull's top make the footprint."""
    opening_m: float = 0.06
    """Width of the morphological opening of the footprint (removes open doors and handles)."""
    front_thickness_m: float = 0.02
    """Thickness of the fronts mounted on the carcass (the generators' 15-25 mm)."""
    refine: bool = True
    """Fit a box to the masks from the hull's footprint (`fit_box`); else the hull's box."""
    outside_weight: float = 2.0
    """What box off a visible mask costs per pixel (`silhouette_score`): more than the cover it
    adds, so that the box settles on the carcass and leaves the fronts and handles out."""
    amodal_outside_weight: float = 1.0
    """The same for amodal carcass masks: the box models the whole mask, so a pixel belongs in
    it when its probability exceeds 0.5."""

    def __post_init__(self):
        if not 0.0 < self.voxel_m <= self.coarse_voxel_m:
            raise ValueError("object pose: need 0 < voxel_m <= coarse_voxel_m")
        if self.min_views < 1 or self.max_misses < 0:
            raise ValueError("object pose: min_views >= 1 and max_misses >= 0")


@dataclass(frozen=True)
class ObjectPoseEstimate:
    """X_WO (4, 4): the object frame O in W (z = 0, yaw about z only); size (3,) m: the
    carcass's depth (along O's x), width (y) and height (z); box (6,) and hull_box (6,): the fitted
    floor box and the hull's (x, y, yaw, depth, width, height; m, rad; fronts included, unless
    fitted to amodal carcass masks);
    voxels: occupied voxels of the fine hull."""

    X_WO: np.ndarray
    size: np.ndarray
    box: np.ndarray
    hull_box: np.ndarray
    voxels: int

    @classmethod
    def from_box(cls, box: np.ndarray, front_thickness_m: float, voxels: int, hull_box: np.ndarray
                 ) -> ObjectPoseEstimate:
        """From a floor box with the fronts: O lies under the carcass's centre, behind them."""
        x, y, yaw, depth, width, height = box
        x_O = np.array([np.cos(yaw), np.sin(yaw)])
        X_WO = np.eye(4)
        X_WO[:2, 0], X_WO[:2, 1] = x_O, [-x_O[1], x_O[0]]
        X_WO[:2, 3] = np.array([x, y]) - front_thickness_m / 2 * x_O
        size = np.array([depth - front_thickness_m, width, height])
        return cls(X_WO, size, np.asarray(box, float), np.asarray(hull_box, float), voxels)

    @property
    def yaw(self) -> float:
        """Rotation of O about W's z, rad."""
        return float(np.arctan2(self.X_WO[1, 0], self.X_WO[0, 0]))

    def size_problem(self, category: str) -> str | None:
        """One line naming the size when it lies outside the category's ranges (with a 25 % margin
        for the hull's coarseness), else None."""
        ranges = category_size_ranges(category)
        for (lo, hi), value, name in zip(ranges, self.size, ("depth", "width", "height"), strict=True):
            if not 0.75 * lo <= value <= 1.25 * hi:
                return (f"estimated {category} {name} {value:.2f} m lies outside the category's "
                        f"{lo:.2f}-{hi:.2f} m (size {self.size[0]:.2f} x {self.size[1]:.2f} x "
                        f"{self.size[2]:.2f} m): wrong masks, camera poses not in metres, or another "
                        "category")
        return None


def category_size_ranges(category: str) -> tuple[tuple[float, float], ...]:
    """The generators' (min, max) carcass depth, width and height of a category, m."""
    from nfr_drake.objects.closet import ClosetRanges
    from nfr_drake.objects.drawer import DrawerRanges
    from nfr_drake.objects.layouts import FurnitureRanges

    if category == "closet":
        r = ClosetRanges()
    elif category == "drawer":
        r = DrawerRanges()
    elif category == "furniture":
        r = FurnitureRanges()
        return (0.25, 0.8), r.width, r.height
    else:
        raise NfrDrakeError(f"unknown category {category!r}")
    return r.depth, r.width, r.height


def background_mask(image: np.ndarray, background_rgb: tuple[float, float, float] | None = None,
                    tolerance: float = 0.03) -> np.ndarray:
    """The object's mask (H, W) float32 0/1 in a photo of the object alone against a uniform
    background: pixels of a uint8 RGB image (H, W, 3) whose colour differs from `background_rgb`
    (in [0, 1]; None: the median colour of the image's border) by more than `tolerance` in some
    channel."""
    rgb = np.asarray(image[..., :3], np.float32) / 255.0
    if background_rgb is None:
        border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]])
        background_rgb = tuple(np.median(border, axis=0))
    return (np.abs(rgb - np.asarray(background_rgb, np.float32)).max(-1) > tolerance).astype(np.float32)


def carve(p_W: np.ndarray, masks: list[np.ndarray], X_WCs: list[np.ndarray],
          cameras: list[PinholeCamera], config: HullConfig = HullConfig()) -> np.ndarray:
    """How many views see each point p_W (n, 3) on the object's mask, (n,) int32, where the hull
    keeps it (held by at least `min_views` images and half of them, inside the mask in all of
    them but `max_misses`), else 0."""
    needed = max(config.min_views, (len(masks) + 1) // 2)
    held = np.zeros(len(p_W), np.int32)
    missed = np.zeros(len(p_W), np.int32)
    for mask, X_WC, camera in zip(masks, X_WCs, cameras, strict=True):
        h, w = mask.shape
        uv, front = project_points(p_W, X_WC, camera)
        col, row = np.floor(uv[:, 0] * w / camera.width), np.floor(uv[:, 1] * h / camera.height)
        inside = front & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        on = np.zeros(len(p_W), bool)
        on[inside] = mask[row[inside].astype(int), col[inside].astype(int)] > config.mask_threshold
        held += inside
        missed += inside & ~on
    return np.where((held >= needed) & (missed <= config.max_misses), held - missed, 0)


def _grid(lo: np.ndarray, hi: np.ndarray, step: float) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Voxel centres (nx * ny * nz, 3) covering [lo, hi] with voxels of `step`, and (nx, ny, nz)."""
    n = np.maximum(np.ceil((hi - lo) / step).astype(int), 1)
    axes = [lo[i] + (np.arange(n[i]) + 0.5) * step for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3), tuple(n)


def _hull(lo: np.ndarray, hi: np.ndarray, step: float, masks, X_WCs, cameras, config: HullConfig
          ) -> np.ndarray:
    """The occupied voxels of the grid of `step` over [lo, hi], carved in slabs: the object's
    part (`_object_part`), (nx, ny, nz) bool."""
    points, shape = _grid(lo, hi, step)
    keep = np.zeros(len(points), np.int32)
    chunk = 1 << 20
    for start in range(0, len(points), chunk):
        keep[start:start + chunk] = carve(points[start:start + chunk], masks, X_WCs, cameras, config)
    return _object_part(keep.reshape(shape))


def _object_part(seen: np.ndarray) -> np.ndarray:
    """The connected part of the kept voxels (seen > 0) that the most views see on the mask (the
    largest among those): with cameras on one side, beams of a few views also meet beyond the
    object, seen there by fewer views."""
    labels, count = ndimage.label(seen > 0)
    if count == 0:
        return seen > 0
    best = ndimage.maximum(seen, labels, np.arange(1, count + 1))
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    return labels == (int(np.lexsort((sizes, best))[-1]) + 1)


def estimate_object_pose(masks: list[np.ndarray], X_WCs: list[np.ndarray],
                         cameras: list[PinholeCamera], config: HullConfig = HullConfig(),
                         category: str | None = None, amodal: bool = False) -> ObjectPoseEstimate:
    """The object's pose X_WO and carcass size from per-view masks.

    masks: (H, W) each, object probability or 0/1 (any size: scaled to its camera's image): the
    object's visible pixels, fronts included, or with `amodal` its carcass's amodal masks (the
    carcass alone, no fronts: the fitted box is the carcass, O under its centre);
    X_WCs: camera poses (4, 4) in W, OpenCV axes, metres, W's floor at z = 0 with z up;
    cameras: their intrinsics; category: when known, the fitted box keeps within its size
    ranges (`category_size_ranges`, 10 % slack), else within 0.1 m and the hull's box + 0.1 m.
    ObjectPoseError when the masks agree on no object.
    """
    if not len(masks) == len(X_WCs) == len(cameras):
        raise ValueError("need one mask and one camera pose per view")
    if len(masks) < config.min_views:
        raise ObjectPoseError(f"object pose: {len(masks)} views, need at least {config.min_views}")
    X_WCs = [np.asarray(X, float) for X in X_WCs]
    front = 0.0 if amodal else config.front_thickness_m
    p_WC = np.stack([X[:3, 3] for X in X_WCs])
    lo = np.array([*(p_WC[:, :2].min(0) - config.search_margin_m), 0.0])
    hi = np.array([*(p_WC[:, :2].max(0) + config.search_margin_m), max(p_WC[:, 2].max(), 0.5)])
    coarse = _hull(lo, hi, config.coarse_voxel_m, masks, X_WCs, cameras, config)
    if not coarse.any():
        raise ObjectPoseError("object pose: the masks agree on no object in front of the cameras "
                              "(empty masks, or camera poses not in a floor frame, z up)")
    index = np.argwhere(coarse)
    fine_lo = np.maximum(lo + (index.min(0) - 1) * config.coarse_voxel_m, [-np.inf, -np.inf, 0.0])
    fine_hi = lo + (index.max(0) + 2) * config.coarse_voxel_m
    step = config.voxel_m
    fine = _hull(fine_lo, fine_hi, step, masks, X_WCs, cameras, config)
    if not fine.any():  # the coarse cells' centres agree, no fine cell's does (a sliver)
        raise ObjectPoseError("object pose: the masks agree on no object at the fine voxel size "
                              f"({step * 100:.1f} cm): a sliver where the views barely overlap")
    area = fine.sum((0, 1))
    typical = np.median(area[area > 0])
    top_slice = int(np.nonzero(area >= 0.5 * typical)[0].max())
    height = fine_lo[2] + (top_slice + 1) * step
    band = [k for k in range(top_slice + 1)
            if config.top_band_m[0] <= height - fine_lo[2] - (k + 0.5) * step <= config.top_band_m[1]]
    columns = (fine[:, :, band].mean(2) >= 0.5) if band else fine[:, :, top_slice]
    radius = max(int(round(config.opening_m / step / 2)), 1)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    opened = cv2.morphologyEx(columns.astype(np.uint8), cv2.MORPH_OPEN, disk) > 0
    cells = np.argwhere(opened if opened.sum() >= 3 else columns)
    if len(cells) < 3:
        raise ObjectPoseError("object pose: the hull has no footprint")
    xy = fine_lo[:2] + (cells + 0.5) * step
    rect = cv2.minAreaRect(xy.astype(np.float32))
    centre = np.array(rect[0], float)
    box = cv2.boxPoints(rect).astype(float)
    edges = [box[1] - box[0], box[2] - box[1]]
    lengths = [float(np.linalg.norm(e)) for e in edges]
    toward = p_WC[:, :2].mean(0) - centre
    facing = [(s * edges[i] / max(lengths[i], 1e-9), lengths[i] + step, lengths[1 - i] + step)
              for i in (0, 1) for s in (1.0, -1.0)]
    x_O, depth, width = max(facing, key=lambda f: float(f[0] @ toward))
    hull_box = np.array([*centre, np.arctan2(x_O[1], x_O[0]), depth, width, height])
    fitted = hull_box
    if config.refine:
        side = min(depth, width)
        starts = [hull_box + [0.0, 0.0, turn, 0.0, 0.0, 0.0] for turn in np.deg2rad((0.0, -25.0, 25.0))]
        starts.append(np.array([*centre, np.arctan2(toward[1], toward[0]), side, side, height]))
        if category is None:
            bounds = [(0.1, hull_box[i] + 0.1) for i in (3, 4, 5)]
        else:
            bounds = [(0.9 * lo, 1.1 * hi) for lo, hi in category_size_ranges(category)]
            bounds[0] = (bounds[0][0] + front, bounds[0][1] + front)
        starts = [np.concatenate([b[:3], np.clip(b[3:], [lo for lo, _ in bounds], [hi for _, hi in bounds])])
                  for b in starts]
        weight = config.amodal_outside_weight if amodal else config.outside_weight
        fitted = _front_facing(fit_box(starts, masks, X_WCs, cameras, bounds, weight), toward)
    return ObjectPoseEstimate.from_box(fitted, front, int(fine.sum()), hull_box)


AMODAL_FALLBACK = "the segmenter's amodal carcass masks agree on no object; its visible masks gave the pose"
"""The warning of `estimate_object_pose_carcass_first` when the amodal masks give no pose."""


def estimate_object_pose_carcass_first(visible: list[np.ndarray], carcass: list[np.ndarray] | None,
                                       X_WCs: list[np.ndarray], cameras: list[PinholeCamera],
                                       config: HullConfig = HullConfig(), category: str | None = None
                                       ) -> tuple[ObjectPoseEstimate, bool, list[str]]:
    """`estimate_object_pose` from the carcass's amodal masks when given (`amodal=True`), else, or
    when they give no pose, from the `visible` masks (each (H, W)). Returns the estimate, whether
    the amodal masks gave it, and warnings ([AMODAL_FALLBACK] when they were given but gave none).
    ObjectPoseError when the visible masks give none either."""
    if carcass is not None:
        try:
            return estimate_object_pose(carcass, X_WCs, cameras, config=config, category=category,
                                        amodal=True), True, []
        except ObjectPoseError:
            pass
    estimate = estimate_object_pose(visible, X_WCs, cameras, config=config, category=category)
    return estimate, False, [AMODAL_FALLBACK] if carcass is not None else []


def box_corners_W(box: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) in W of a floor box (x, y, yaw, depth, width, height): centre of its
    footprint at (x, y), its depth along the yawed x, standing on z = 0."""
    x, y, yaw, d, w, h = box
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[sx * d / 2, sy * w / 2, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, h)])
    return np.column_stack([local[:, 0] * c - local[:, 1] * s + x, local[:, 0] * s + local[:, 1] * c + y,
                            local[:, 2]])


def box_image_rect(box: np.ndarray, X_WC: np.ndarray, camera: PinholeCamera, shape: tuple[int, int]
                   ) -> tuple[float, float, float, float] | None:
    """The bounding rectangle (x0, y0, x1, y1), pixels of an image of `shape` (H, W) taken by
    `camera` (scaled) at X_WC, of the floor box's corners (x, y, yaw, depth, width, height); it may
    reach beyond the image. None when a corner lies behind the camera."""
    h, w = shape
    uv, front = project_points(box_corners_W(box), X_WC, camera)
    if not front.all():
        return None
    uv = uv * [w / camera.width, h / camera.height]
    return float(uv[:, 0].min()), float(uv[:, 1].min()), float(uv[:, 0].max()), float(uv[:, 1].max())


def box_silhouette(box: np.ndarray, X_WC: np.ndarray, camera: PinholeCamera, shape: tuple[int, int]
                   ) -> np.ndarray:
    """The floor box's silhouette (shape) float32 in [0, 1], anti-aliased, in an image of `shape`
    (H, W) taken by `camera` (scaled) at X_WC; the whole image when a corner lies behind the camera
    (the box would hold or touch the camera, which stands outside the object)."""
    h, w = shape
    uv, front = project_points(box_corners_W(box), X_WC, camera)
    if not front.all():
        return np.ones(shape, np.float32)
    image = np.zeros(shape, np.uint8)
    uv = (uv * [w / camera.width, h / camera.height] - 0.5) * 16
    cv2.fillConvexPoly(image, cv2.convexHull(np.round(uv).astype(np.int32)), 255,
                       lineType=cv2.LINE_AA, shift=4)
    return image.astype(np.float32) / 255.0


def silhouette_score(box: np.ndarray, masks: list[np.ndarray], X_WCs: list[np.ndarray],
                     cameras: list[PinholeCamera], outside_weight: float = 2.0) -> float:
    """How well the floor box's silhouettes lie on the masks, at most 1: (covered mask - weight x
    silhouette off the mask) / mask, summed over views. Mask outside the box (an open door, a
    handle) costs nothing but the cover it does not add, so the box settles on the carcass."""
    covered = off = total = 0.0
    for mask, X_WC, camera in zip(masks, X_WCs, cameras, strict=True):
        sil = box_silhouette(box, X_WC, camera, mask.shape)
        inter = float(np.minimum(sil, mask).sum())
        covered += inter
        off += float(sil.sum()) - inter
        total += float(mask.sum())
    return (covered - outside_weight * off) / max(total, 1e-9)


def _front_facing(box: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """The same floor box turned by a multiple of 90 degrees (depth and width swapped on odd
    turns) so that its +x faces `toward` (2,), xy."""
    x, y, yaw, d, w, h = box
    turns = [(k, np.array([np.cos(yaw + k * np.pi / 2), np.sin(yaw + k * np.pi / 2)])) for k in range(4)]
    k = max(turns, key=lambda t: float(t[1] @ toward))[0]
    d, w = (w, d) if k % 2 else (d, w)
    return np.array([x, y, np.angle(np.exp(1j * (yaw + k * np.pi / 2))), d, w, h])


def fit_box(starts: list[np.ndarray], masks: list[np.ndarray], X_WCs: list[np.ndarray],
            cameras: list[PinholeCamera], bounds: list[tuple[float, float]], outside_weight: float = 2.0
            ) -> np.ndarray:
    """The floor box (x, y, yaw, depth, width, height) whose silhouettes best lie on the masks
    (`silhouette_score` with `outside_weight`) with its depth, width and height within `bounds`
    ((min, max) each, m; a box outside costs 10 per m): Nelder-Mead from each start (an open door
    turns the hull's footprint), restarted from its result with a smaller simplex; the best of them."""
    from scipy.optimize import minimize

    masks = [np.clip(np.asarray(m, np.float32), 0.0, 1.0) for m in masks]
    lo, hi = np.array(bounds).T

    def cost(box: np.ndarray) -> float:
        size = np.clip(box[3:], lo, hi)
        excess = float(np.abs(box[3:] - size).sum())
        return -silhouette_score(np.concatenate([box[:3], size]), masks, X_WCs, cameras,
                                 outside_weight) + 10.0 * excess

    fits = []
    for start in starts:
        best = np.asarray(start, float)
        for scale in (1.0, 0.3):
            steps = scale * np.array([0.05, 0.05, 0.1, 0.08, 0.08, 0.05])
            result = minimize(cost, best, method="Nelder-Mead",
                              options={"initial_simplex": np.vstack([best, best + np.diag(steps)]),
                                       "xatol": 1e-4, "fatol": 1e-6, "maxfev": 600})
            best = result.x
        fits.append((result.fun, tuple(best)))
    best = np.array(min(fits)[1])
    return np.concatenate([best[:3], np.clip(best[3:], lo, hi)])
