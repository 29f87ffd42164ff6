"""The object's true floor box against the box estimated from its masks, in held-out rooms.

    python scripts/object_pose_figure.py --category drawer --rooms 9 10 \
        --out docs/images/object_pose_drawer.png

Rooms as in `benchmarks/object_pose_rooms.py` (`--style heldout`, seed 900, one articulation of 8
views, 128 px), in O (X_WO = identity). Per room three rows of four views: the photo, the target's
labels (true masks), the segmenter's masks; over them the true box (green: the carcass with its
front, from the object's parameters) and the box `estimate_object_pose` fits to those masks (red).
Prints per room: q, the share of the true box's silhouette that the labels cover (what is not
covered is hidden by clutter, neighbours or the arm), and per mask set the estimated box, the pose
error and `silhouette_score` of the estimated and of the true box.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
import numpy as np
import tyro

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from nfr_drake.data.camera import PinholeCamera  # noqa: E402
from nfr_drake.data.room_dataset import RoomDatasetSpec, render_room_arrays  # noqa: E402
from nfr_drake.data.rooms import RoomDistribution  # noqa: E402
from nfr_drake.perception.object_pose import (  # noqa: E402
    ObjectPoseError,
    box_corners_W,
    box_silhouette,
    estimate_object_pose,
    project_points,
    silhouette_score,
)

EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


def _draw(ax, box: np.ndarray, X_OC: np.ndarray, camera: PinholeCamera, color: str) -> None:
    uv, _ = project_points(box_corners_W(box), X_OC, camera)
    for a, b in EDGES:
        ax.plot(uv[[a, b], 0] - 0.5, uv[[a, b], 1] - 0.5, color=color, lw=0.8)


def main(category: str = "drawer", rooms: list[int] = [9, 10], seed: int = 900,  # noqa: B006
         segmenter: Path = Path("models/segmenter"), out: Path = Path("object_pose.png")) -> None:
    from nfr_drake.perception.segmentation.model import load_segmenter

    net, _ = load_segmenter(segmenter)
    spec = RoomDatasetSpec(category, max(rooms) + 1, articulations=1, views=8, size=128, seed=seed,
                           room=RoomDistribution(style="heldout"))
    shown = [0, 2, 4, 6]
    fig, axes = plt.subplots(3 * len(rooms), len(shown), figsize=(2 * len(shown), 6 * len(rooms)),
                             squeeze=False)
    for r, i in enumerate(rooms):
        arrays, meta, _, _ = render_room_arrays(spec, i)
        camera, X_OC = PinholeCamera.from_json(meta["camera"]), list(np.array(meta["X_OC"])[0])
        p = meta["params"]
        front = p.get("front_thickness", p.get("door_thickness", 0.02))
        true_box = np.array([front / 2, 0.0, 0.0, p["depth"] + front, p["width"], p["height"]])
        labels = [(label > 0).astype(np.float32) for label in arrays["label"][0]]
        sets = {"labels": labels, "segmenter": [net.object_mask(rgb) for rgb in arrays["rgb"][0]]}
        sils = [box_silhouette(true_box, X, camera, m.shape) for m, X in zip(labels, X_OC, strict=True)]
        covered = np.mean([np.minimum(s, m).sum() / s.sum() for s, m in zip(sils, labels, strict=True)])
        print(f"{category} {i}: q {np.round(meta['q'][0], 2).tolist()}, true box (depth with front, width, "
              f"height) {np.round(true_box[3:], 3).tolist()}, labels cover {covered:.2f} of its silhouette")
        boxes = {}
        for name, masks in sets.items():
            try:
                est = estimate_object_pose(masks, X_OC, [camera] * len(X_OC), category=category)
            except ObjectPoseError as err:
                print(f"  {name}: {err}")
                continue
            boxes[name] = est.box
            cm = 100 * np.linalg.norm(est.X_WO[:2, 3])
            print(f"  {name}: box {np.round(est.box[3:], 3).tolist()}, {cm:.1f} cm, "
                  f"{abs(math.degrees(est.yaw)):.1f} deg; score estimated "
                  f"{silhouette_score(est.box, masks, X_OC, [camera] * len(X_OC)):.3f}, true "
                  f"{silhouette_score(true_box, masks, X_OC, [camera] * len(X_OC)):.3f}")
        for c, v in enumerate(shown):
            images = [arrays["rgb"][0][v], labels[v], sets["segmenter"][v]]
            for k, (image, title) in enumerate(zip(images, ("photo", "labels", "segmenter"), strict=True)):
                ax = axes[3 * r + k, c]
                ax.imshow(image, cmap="gray", vmin=0, vmax=1)
                _draw(ax, true_box, X_OC[v], camera, "lime")
                if title in boxes:
                    _draw(ax, boxes[title], X_OC[v], camera, "red")
                ax.set_title(f"{category} {i} view {v}: {title}", fontsize=7)
                ax.set_xlim(0, camera.width)
                ax.set_ylim(camera.height, 0)
                ax.axis("off")
    plt.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    plt.savefig(out, dpi=80)
    print(f"wrote {out}")


if __name__ == "__main__":
    tyro.cli(main)
