"""Amodal carcass labels: the target's carcass silhouette in each photo as if nothing hid it.

The label images of a room dataset (`label.npy`) hold the target's VISIBLE pixels: clutter on its
top, a neighbour, the arm, and its own doors and drawers hide parts of its carcass. The amodal
label is the silhouette of the carcass body alone (the visuals of the SDFormat link `carcass`:
panels, shelves, plinths, legs), with nothing in front of it, no fronts included: what a floor box
of the carcass should cover (`perception.object_pose`).

Each visual is a convex solid (box, cylinder, sphere), given by points whose convex hull it is
(`carcass_solids`); its silhouette in a view is the filled convex hull of their projection (exact
for a pinhole camera; with lens distortion, straight edges are drawn straight between the
distorted corners), and the label is the union over the solids (`amodal_mask`).

Files: `carcass_amodal.npy` uint8 (A, V, S, S), 1 on the carcass, 0 elsewhere, beside `label.npy`
in each room folder; `nfr-drake label-amodal DIR...` writes it into existing room datasets
(resumable, one file per room, written atomically), `generate-rooms` writes it too.
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.errors import DatasetError
from nfr_drake.objects.articulated import rotation_from_rpy

AMODAL_FILE = "carcass_amodal.npy"
CARCASS_LINK = "carcass"
ROUND_SEGMENTS = 32
"""Points around a cylinder's rim or a sphere's circles (the polygon circumscribes the circle)."""


def _pose(element: ET.Element | None) -> np.ndarray:
    """The 4x4 transform of an SDFormat <pose> element (x y z roll pitch yaw), identity if None."""
    X = np.eye(4)
    if element is not None and element.text and element.text.strip():
        v = [float(s) for s in element.text.split()]
        X[:3, :3] = rotation_from_rpy(tuple(v[3:6]))
        X[:3, 3] = v[:3]
    return X


def _solid_points(geometry: ET.Element) -> np.ndarray:
    """Points (n, 3) in the geometry's frame whose convex hull holds the shape (box, cylinder along
    z, sphere); DatasetError on any other shape."""
    circumscribe = 1.0 / np.cos(np.pi / ROUND_SEGMENTS)
    angles = np.linspace(0.0, 2.0 * np.pi, ROUND_SEGMENTS, endpoint=False)
    if (box := geometry.find("box")) is not None:
        half = np.array([float(s) for s in box.findtext("size").split()]) / 2.0
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        return signs * half
    if (cyl := geometry.find("cylinder")) is not None:
        r, length = float(cyl.findtext("radius")) * circumscribe, float(cyl.findtext("length"))
        rim = np.column_stack([r * np.cos(angles), r * np.sin(angles)])
        return np.concatenate([np.column_stack([rim, np.full(len(rim), z)])
                               for z in (-length / 2, length / 2)])
    if (sphere := geometry.find("sphere")) is not None:
        r = float(sphere.findtext("radius")) * circumscribe**2
        lat = np.linspace(-np.pi / 2, np.pi / 2, ROUND_SEGMENTS // 2 + 1)
        a, b = np.meshgrid(angles, lat)
        return r * np.column_stack([(np.cos(b) * np.cos(a)).ravel(), (np.cos(b) * np.sin(a)).ravel(),
                                    np.sin(b).ravel()])
    raise DatasetError(f"amodal label: unsupported carcass geometry {[c.tag for c in geometry]}")


def carcass_solids(sdf: str, link: str = CARCASS_LINK) -> list[np.ndarray]:
    """The carcass's visuals as convex solids: one array (n, 3) of points in O (the model frame)
    per visual of `link` in an SDFormat model (`object.sdf` of a room folder)."""
    root = ET.fromstring(sdf)
    links = [el for el in root.iter("link") if el.get("name") == link]
    if not links:
        raise DatasetError(f"amodal label: the model has no link {link!r}")
    X_OL = _pose(links[0].find("pose"))
    solids = []
    for visual in links[0].findall("visual"):
        X_OV = X_OL @ _pose(visual.find("pose"))
        points = _solid_points(visual.find("geometry"))
        solids.append(points @ X_OV[:3, :3].T + X_OV[:3, 3])
    if not solids:
        raise DatasetError(f"amodal label: the link {link!r} has no visuals")
    return solids


def _clip_near(p_C: np.ndarray, near: float) -> np.ndarray:
    """The points of a convex solid (n, 3) in camera coordinates clipped to z >= near: those in
    front and the crossings of the plane z = near by the segments between front and back points
    (their hull is the clipped solid's)."""
    front, back = p_C[p_C[:, 2] >= near], p_C[p_C[:, 2] < near]
    if len(back) == 0 or len(front) == 0:
        return front
    a, b = np.repeat(front, len(back), 0), np.tile(back, (len(front), 1))
    t = (a[:, 2] - near) / (a[:, 2] - b[:, 2])
    return np.concatenate([front, a + t[:, None] * (b - a)])


def amodal_mask(solids: list[np.ndarray], X_OC: np.ndarray, camera: PinholeCamera,
                shape: tuple[int, int] | None = None, near: float = 0.01) -> np.ndarray:
    """The union of the solids' silhouettes, uint8 (H, W) 0/1, in an image of `shape` (default the
    camera's) taken by `camera` (scaled) at X_OC (4, 4, OpenCV axes, m); a pixel is on when its
    centre lies inside a projected solid."""
    h, w = shape or (camera.height, camera.width)
    cam = camera if (w, h) == (camera.width, camera.height) else camera.scaled(w, h)
    X_CO = np.linalg.inv(np.asarray(X_OC, float))
    image = np.zeros((h, w), np.uint8)
    for points in solids:
        p_C = _clip_near(points @ X_CO[:3, :3].T + X_CO[:3, 3], near)
        if len(p_C) < 3:
            continue
        xy = p_C[:, :2] / p_C[:, 2:]
        if cam.has_distortion:
            uv = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), np.zeros(3), np.zeros(3),
                                   cam.K_opencv, cam.dist_opencv)[0].reshape(-1, 2)
        else:
            uv = xy * [cam.fx, cam.fy] + [cam.cx - 0.5, cam.cy - 0.5]  # OpenCV: pixel centre at 0
        uv = np.clip(uv, -4.0 * max(h, w), 5.0 * max(h, w))  # far outside the image: the same fill
        hull = cv2.convexHull(np.round(uv * 16).astype(np.int32))
        cv2.fillConvexPoly(image, hull, 1, lineType=cv2.LINE_8, shift=4)
    return image


def amodal_labels(sdf: str, X_OC: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """The amodal carcass label of every view, uint8 (A, V, H, W), for camera poses X_OC
    (A, V, 4, 4) of the model in `sdf`."""
    solids = carcass_solids(sdf)
    X_OC = np.asarray(X_OC, float)
    out = np.zeros((*X_OC.shape[:2], camera.height, camera.width), np.uint8)
    for a in range(X_OC.shape[0]):
        for v in range(X_OC.shape[1]):
            out[a, v] = amodal_mask(solids, X_OC[a, v], camera)
    return out


def label_room(folder: Path) -> bool:
    """Write `carcass_amodal.npy` into one room folder from its object.sdf and meta.json (camera,
    X_OC), atomically; False when it is there already."""
    folder = Path(folder)
    if (folder / AMODAL_FILE).is_file():
        return False
    meta = json.loads((folder / "meta.json").read_text())
    labels = amodal_labels((folder / "object.sdf").read_text(), np.array(meta["X_OC"]),
                           PinholeCamera.from_json(meta["camera"]))
    tmp = folder / f".{AMODAL_FILE}.tmp-{os.getpid()}.npy"
    np.save(tmp, labels)
    os.replace(tmp, folder / AMODAL_FILE)
    return True


def label_amodal_command(data: list[Path]) -> None:
    """Write the amodal carcass labels (`carcass_amodal.npy`, uint8 (A, V, S, S)) into room
    datasets (`nfr-drake generate-rooms`); rooms that hold them are skipped, so an interrupted
    run resumes.

    Args:
        data: room dataset folders.
    """
    from nfr_drake.data.room_dataset import room_dirs

    for root in data:
        rooms = room_dirs(root)
        written = sum(label_room(folder) for folder in rooms)
        print(f"{root}: amodal carcass labels written for {written} of {len(rooms)} rooms")
