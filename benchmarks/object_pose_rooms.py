"""Object pose error from masks: unseen objects in random rooms (held-out textures and lights), or alone.

    python benchmarks/object_pose_rooms.py --category closet --rooms 12
    python benchmarks/object_pose_rooms.py --category closet --rooms 12 --setting alone
    python benchmarks/object_pose_rooms.py --category closet --rooms 12 --amodal
    python benchmarks/object_pose_rooms.py --category closet --rooms 12 --amodal --segmenter models/segmenter
    python benchmarks/object_pose_rooms.py --category closet --rooms 12 --amodal \
        --segmenter models/segmenter --crop

Room i of `nfr-drake generate-rooms` (its spec with `--style heldout`, seed `seed`; one articulation
of `views` cameras, `size` px) is rendered in memory; its camera poses are moved into a floor frame
W by a random X_WO (yaw in [-pi, pi], x and y in [-2, 2] m) and `estimate_object_pose` runs on the
views' masks: the target's labels (true masks), or, with `--segmenter DIR`, the segmenter's
probabilities (with `--crop`, those of the crop stage: `segmentation.crop.posed_close_look`, a
second look at the crop around the box of the pose from the first masks). With `--amodal` the
masks are the carcass's amodal masks instead (the carcass alone as if nothing hid it, no fronts):
the true ones (`carcass_amodal`, `data.amodal`) or the segmenter's amodal output
(`Segmenter.carcass_amodal`; with `--crop` its second look, `posed_carcass_look`, as the
pipeline's), and the box is fitted as the carcass (`amodal=True`). With `--setting alone`
the object of `nfr-drake captures` (seed `seed`, index i) stands alone before the training
renders' background, photographed by `views` cameras of the paper's distribution
(`CameraDistribution`) at a q drawn as the rooms' (shut with probability 0.4, else uniform), its
labels as masks. Prints one line per room and the median position (cm)
and yaw (degrees) errors, over all rooms and over those whose fronts are all shut.
"""

from __future__ import annotations

import datetime
import math
import os
import time
from pathlib import Path

import numpy as np
import tyro

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.room_dataset import RoomDatasetSpec, render_room_arrays
from nfr_drake.data.rooms import RoomDistribution
from nfr_drake.perception.object_pose import ObjectPoseError, estimate_object_pose


def _alone(category: str, seed: int, index: int, views: int, size: int, amodal: bool = False):
    """(masks, X_OC (V, 4, 4), camera, q) of an object alone, its labels as masks (with `amodal`,
    its carcass's amodal labels)."""
    from nfr_drake.data.camera_placement import CameraDistribution
    from nfr_drake.data.render import ObjectRenderer
    from nfr_drake.data.room_dataset import SHUT_PROBABILITY
    from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object

    rng = object_rng(SEED_DOMAIN_CAPTURE, seed, index)
    obj = sample_object(category, rng)
    q = rng.uniform(0.0, 1.0, obj.num_fronts) * (rng.uniform(size=obj.num_fronts) >= SHUT_PROBABILITY)
    camera = PinholeCamera.from_fov(size, size, math.radians(50.0))
    X_OC = CameraDistribution().sample(rng, views, obj.look_at_target(), obj.swept_bounds(), camera)
    if amodal:
        from nfr_drake.data.amodal import amodal_labels
        from nfr_drake.data.object_records import portable_sdformat

        labels = amodal_labels(portable_sdformat(obj)[0], X_OC[None], camera)[0]
        return [m.astype(np.float32) for m in labels], X_OC, camera, q
    renderer = ObjectRenderer(obj, camera)
    masks = [(renderer.render(q, X).label > 0).astype(np.float32) for X in X_OC]
    return masks, X_OC, camera, q


def main(category: str = "closet", rooms: int = 12, views: int = 8, size: int = 128, seed: int = 900,
         setting: str = "room", segmenter: Path | None = None, crop: bool = False,
         amodal: bool = False) -> None:
    if crop and segmenter is None:
        raise SystemExit("--crop is the segmenter's second look: give --segmenter")
    if setting == "alone" and segmenter is not None:
        raise SystemExit("--setting alone measures the true labels: no --segmenter")
    net = None
    if segmenter is not None:
        from nfr_drake.perception.segmentation.model import load_segmenter

        net, _ = load_segmenter(segmenter)
    spec = RoomDatasetSpec(category, rooms, articulations=1, views=views, size=size, seed=seed,
                           room=RoomDistribution(style="heldout"))
    rows = []
    for i in range(rooms):
        if setting == "alone":
            masks, X_OC, camera, q = _alone(category, seed, i, views, size, amodal)
        else:
            arrays, meta, _, _ = render_room_arrays(spec, i)
            camera, q = PinholeCamera.from_json(meta["camera"]), np.array(meta["q"][0])
            X_OC = np.array(meta["X_OC"])[0]
            if net is None and amodal:
                masks = [m.astype(np.float32) for m in arrays["carcass_amodal"][0]]
            elif net is None:
                masks = [(label > 0).astype(np.float32) for label in arrays["label"][0]]
            elif amodal and crop:
                from nfr_drake.perception.segmentation.crop import posed_carcass_look

                masks = posed_carcass_look(net, list(arrays["rgb"][0]), list(X_OC), [camera] * views,
                                           category)
            elif amodal:
                masks = [net.carcass_amodal(rgb) for rgb in arrays["rgb"][0]]
            elif crop:
                from nfr_drake.perception.segmentation.crop import posed_close_look

                masks = posed_close_look(net, list(arrays["rgb"][0]), list(X_OC), [camera] * views, category)
            else:
                masks = [net.object_mask(rgb) for rgb in arrays["rgb"][0]]
        rng = np.random.default_rng([seed, i])
        yaw = rng.uniform(-math.pi, math.pi)
        X_WO = np.eye(4)
        X_WO[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        X_WO[:2, 3] = rng.uniform(-2.0, 2.0, 2)
        started = time.perf_counter()
        try:
            estimate = estimate_object_pose(masks, [X_WO @ X for X in X_OC],
                                            [camera] * views, category=category, amodal=amodal)
        except ObjectPoseError as err:
            print(f"room {i}: {err}")
            rows.append((math.inf, math.inf, False))
            continue
        d = np.linalg.inv(X_WO) @ estimate.X_WO
        cm = 100.0 * float(np.linalg.norm(d[:2, 3]))
        deg = abs(math.degrees(math.atan2(d[1, 0], d[0, 0])))
        shut = bool(np.all(q == 0.0))
        rows.append((cm, deg, shut))
        print(f"room {i}: {'shut' if shut else 'open'} q {np.round(q, 2).tolist()}: "
              f"{cm:.2f} cm, {deg:.2f} deg; size {np.round(estimate.size, 3).tolist()} "
              f"({time.perf_counter() - started:.1f} s)")
    table = np.array(rows, dtype=float)
    for name, sel in (("all", np.ones(len(rows), bool)), ("shut", table[:, 2] > 0)):
        if sel.any():
            cm, deg = np.median(table[sel, 0]), np.median(table[sel, 1])
            within = np.mean((table[sel, 0] <= 2.0) & (table[sel, 1] <= 2.0))
            print(f"{category} {name} ({sel.sum()} rooms): median {cm:.2f} cm, {deg:.2f} deg; "
                  f"within 2 cm and 2 deg: {100 * within:.0f} %")
    print(f"{datetime.date.today()}, {os.cpu_count()}-core CPU, {setting}, masks: "
          f"{'segmenter ' + str(segmenter) if segmenter else 'true labels'}{', crop stage' if crop else ''}"
          f"{', amodal carcass' if amodal else ''}")


if __name__ == "__main__":
    tyro.cli(main)
