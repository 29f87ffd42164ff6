# %% [markdown]
# # Tutorial 1: articulated objects and their Drake renders
#
# nfr-drake learns a neural field of one object *category* from images that Drake renders of
# procedurally generated objects. This tutorial samples a closet and a drawer, looks at their
# keypoints as the articulation q goes from 0 (closed) to 1 (open), renders them with Drake's
# RgbdSensor (RGB, semantic labels, depth) and writes a small dataset.
#
# Run it as plain Python: `python tutorials/01_objects_and_data.py`. Set `NFR_TUTORIAL_OUT` to
# choose where figures go (default `docs/images`).

# %%
import math
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.generate import generate_dataset
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.data.shards import DatasetSpec
from nfr_drake.data.visualize import colorize_labels, colorize_parts, image_grid
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.objects.furniture import sample_furniture

out_dir = Path(os.environ.get("NFR_TUTORIAL_OUT", "docs/images"))
out_dir.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## Sampling objects
# Each object is drawn from its own random stream: `object_rng(domain, seed, index)`. The same
# triple always gives the same object. Positions are in the object frame O: origin on the floor
# under the carcass centre, +x out of the front, +z up.

# %%
closet = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 2))
drawer = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 0, 5))
for obj in (closet, drawer):
    p = obj.params
    print(f"{obj.category}: {p['width']:.2f} x {p['depth']:.2f} x {p['height']:.2f} m, "
          f"{obj.joint_type} joint '{obj.joint_name}', q = 1 is {obj.joint_upper:.3f} "
          f"{'rad' if obj.joint_type == 'revolute' else 'm'}")

# %% [markdown]
# ## Keypoints along q
# The closet's handle moves on an arc about the hinge axis; the hinges and the goal stay put.
# The drawer's handle and goal move in a straight line along +x.

# %%
for obj in (closet, drawer):
    for q in (0.0, 0.5, 1.0):
        kp = obj.keypoints(q)
        print(f"{obj.category} q={q:.1f}: " + ", ".join(
            f"{name} ({v[0]:+.3f}, {v[1]:+.3f}, {v[2]:+.3f})" for name, v in kp.items()))

# %% [markdown]
# ## Rendering with Drake
# `ObjectRenderer` puts the object in a MultibodyPlant and renders it with an RgbdSensor on
# RenderEngineVtk. Each view gives RGB, a semantic label image (0 background, 1 carcass,
# 2 door or drawer, 3 handle) and depth. Cameras use OpenCV axes: x right, y down, z forward.

# %%
camera = PinholeCamera.from_fov(128, 128, math.radians(50))
rows = []
for obj, eye in ((closet, (1.5, 0.6, 1.0)), (drawer, (1.5, -0.5, 0.9))):
    renderer = ObjectRenderer(obj, camera)
    X_OC = look_at(np.array(eye), obj.look_at_target())
    views = [renderer.render(q, X_OC) for q in (0.0, 0.33, 0.67, 1.0)]
    rows.append([v.rgb for v in views])
    rows.append([colorize_labels(v.label) for v in views])
    depth = views[0].depth
    print(f"{obj.category}: depth {np.nanmin(depth):.2f}-{depth[np.isfinite(depth)].max():.2f} m")
figure = image_grid(rows)
cv2.imwrite(str(out_dir / "tutorial_01_renders.png"), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
print("wrote", out_dir / "tutorial_01_renders.png")

# %% [markdown]
# ## A small dataset
# `nfr-drake generate` does the same at scale, in worker processes, resumably. Here is its
# library form, writing 3 closets x 4 articulations x 2 views into a temporary folder, and the
# torch Dataset that reads it without loading everything into memory.

# %%
with tempfile.TemporaryDirectory() as tmp:
    spec = DatasetSpec("closet", objects=3, articulations=4, views=2, size=64)
    generate_dataset(spec, Path(tmp), workers=1, progress=False)
    dataset = RenderedDataset(tmp)
    item = dataset[5]
    print(f"{len(dataset)} images; item 5: rgb {tuple(item.rgb.shape)}, q = {item.q.item():.2f}, "
          f"handle at {item.keypoints[0].numpy().round(3)} m")

# %% [markdown]
# ## Furniture: several doors and drawers
# The `furniture` category draws pieces of real kinds (cabinets, wardrobes, chests, desks, tables,
# kitchen runs, fridges, sideboards) with one to eight fronts, each a door or drawer on its own
# joint (docs/FURNITURE.md). Fronts are in canonical order: columns left to right as seen from the
# front, top to bottom within a column; front k is link `front{k}` on joint `front{k}_joint`.
# q is one value per front; keypoints come per front (doors: handle, hinge_top, hinge_bottom,
# goal; drawers: handle, goal). The renderer also returns a part-index image: which front each
# pixel shows, -1 for the carcass and the background.

# %%
piece = sample_furniture(object_rng(SEED_DOMAIN_TRAIN, 0, 3), kind="base_cabinet")
print(f"{piece.params['kind']}: {piece.num_fronts} fronts "
      + ", ".join(f"{f.link_name} {f.kind}" for f in piece.fronts))
q = np.zeros(piece.num_fronts)
q[0] = 1.0  # open the first front only
for k, kp in enumerate(piece.front_keypoints(q)):
    print(f"front {k} at q={q[k]:.0f}: handle ({kp['handle'][0]:+.3f}, {kp['handle'][1]:+.3f}, "
          f"{kp['handle'][2]:+.3f}), goal ({kp['goal'][0]:+.3f}, {kp['goal'][1]:+.3f}, {kp['goal'][2]:+.3f})")
renderer = ObjectRenderer(piece, camera)
lo, hi = piece.base_bounds()
X_OC = look_at(np.array([1.8, 0.7, 1.3]), (lo + hi) / 2)
views = [renderer.render(qs, X_OC) for qs in (0.0, q, 0.6)]
figure = image_grid([[v.rgb for v in views], [colorize_labels(v.label) for v in views],
                     [colorize_parts(v.part) for v in views]])
cv2.imwrite(str(out_dir / "tutorial_01_furniture.png"), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
print("fronts seen:", sorted(set(np.unique(views[0].part).tolist()) - {-1}))
print("wrote", out_dir / "tutorial_01_furniture.png")
