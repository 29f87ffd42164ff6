# %% [markdown]
# # Tutorial 3: photos of a room -> camera poses -> fit -> plan, all on the command line
#
# Tutorial 2 turned a folder of photos into a capture set. Here the photos show a whole room: a
# closet among other furniture and clutter, a ChArUco board lying on the floor, taken through a
# distorting lens. Four commands take them to a simulated robot opening the closet:
#
# 1. `nfr-drake poses --charuco --world floor`: camera poses in metres, in a floor frame W under
#    the board (z up, the floor at z = 0), checked against the floor the photos show;
# 2. `nfr-drake infer --estimate-pose --masks segmenter`: the 2D segmenter finds the closet in
#    each photo, the masks give the closet's pose X_WO on the floor, the neural field is fitted
#    to the photos painted in its training background off the masks, and keypoints and their
#    trajectory come out in W;
# 3. `nfr-drake plan --keypoints result.json`: the planner opens the closet using the fitted
#    keypoints alone; the motion is simulated on the true closet and written as an HTML replay.
#
# The "photos" are Drake renders, so every stage can be checked against the truth. With real
# photos, start at step 2 with your own folder. Run as plain Python:
# `python tutorials/03_room_photos_to_plan.py` (several minutes on 2 CPU cores; with
# `NFR_TUTORIAL_QUICK=1`, smaller photos and a shorter fit, as the tests run it). Figures go to
# `NFR_TUTORIAL_OUT` (default `docs/images`).

# %%
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np
import torch

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.rooms import RoomDistribution
from nfr_drake.data.visualize import image_grid
from nfr_drake.inference.forward import render_view
from nfr_drake.inference.infer import object_masks
from nfr_drake.nfr.checkpoint import load_model
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.perception.charuco import CharucoBoardSpec
from nfr_drake.perception.handle_triangulation import project
from nfr_drake.perception.synthetic import (
    RoomSpec,
    SyntheticPhotoScene,
    furnished_room,
    orbit_poses,
    write_photo_folder,
)

QUICK = os.environ.get("NFR_TUTORIAL_QUICK") == "1"
SIZE, VIEWS = (640, 8) if QUICK else (1024, 10)
FIT = ["--fit.preset", "fast"] + (["--fit.max-steps", "60"] if QUICK else [])
ROOT = Path(__file__).resolve().parents[1]
NFR_DRAKE = shutil.which("nfr-drake") or str(Path(sys.executable).with_name("nfr-drake"))
torch.set_num_threads(1)
out_dir = Path(os.environ.get("NFR_TUTORIAL_OUT", "docs/images"))
out_dir.mkdir(parents=True, exist_ok=True)
work = Path(tempfile.mkdtemp(prefix="nfr_tutorial_03_"))


def nfr_drake(*args) -> subprocess.CompletedProcess:
    """Run one `nfr-drake` command, echo it and its output; a user error (exit 2) stops here."""
    args = [str(a) for a in args]
    print("$ nfr-drake", " ".join(args), flush=True)
    done = subprocess.run([NFR_DRAKE, *args], capture_output=True, text=True,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    print(done.stdout.rstrip())
    if done.returncode == 2:
        sys.exit(f"nfr-drake {args[0]} refused: {done.stderr.strip().splitlines()[-1]}")
    return done


def save(name: str, rgb: np.ndarray) -> None:
    cv2.imwrite(str(out_dir / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    print("wrote", out_dir / name)


# %% [markdown]
# ## 1. Photos of a room
# An unseen closet (drawn with seed 21; the model was trained on seed 0), shut, stands in a
# room of `nfr_drake.data.rooms`: textured floor and walls, other furniture, clutter (some of it
# on the closet), room lights. A ChArUco board (5 x 7 squares of 10 cm, an A1 print on 2 mm card)
# lies on the floor in front of it, turned 30 degrees. The photos are taken on an arc in front
# of the closet through a lens with barrel distortion. `truth.json` keeps what the pipeline
# must find: the camera poses, the board, the floor frame under it and the closet's keypoints.

# %%
SEED = 21
closet = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, SEED, 0))
lo, hi = closet.swept_bounds()
board = CharucoBoardSpec(squares=(5, 7), square_m=0.1, marker_m=0.075, thickness_m=0.002)
room = RoomSpec(board=board, p_OB=(hi[0] + 0.1, -0.25, board.thickness_m), board_yaw_deg=30.0)
camera = PinholeCamera.from_fov(SIZE, SIZE * 3 // 4, np.deg2rad(55))
X_OCs = orbit_poses(VIEWS, np.array([hi[0] - 0.1, (lo[1] + hi[1]) / 2, 0.4 * hi[2]]),
                    distance_m=max(1.7, 2.2 * hi[2]), azimuth_deg=(-45.0, 45.0), elevation_deg=(20.0, 35.0))
furnishing = furnished_room(np.random.default_rng(1), closet, X_OCs[:, :3, 3], room,
                            RoomDistribution(neighbours=(1, 2), beside_probability=0.0, clutter=(5, 9),
                                             robot_probability=0.0, cut_probability=0.0))
scene = SyntheticPhotoScene(closet, 0.0, camera, room, furnishing=furnishing)
photos = work / "photos"
write_photo_folder(photos, scene, X_OCs, distortion=(-0.1, 0.02, 3e-4, -2e-4))
truth = json.loads((photos / "truth.json").read_text())
(work / "camera.json").write_text(json.dumps(truth["camera"]))
names = sorted(truth["X_OC"])
thumbs = [cv2.resize(cv2.cvtColor(cv2.imread(str(photos / n)), cv2.COLOR_BGR2RGB), (256, 192),
                     interpolation=cv2.INTER_AREA) for n in names]
half = (len(thumbs) + 1) // 2
save("tutorial_03_photos.png", image_grid([thumbs[:half], thumbs[half:2 * half]]))

# %% [markdown]
# ## 2. Camera poses in a floor frame
# `--world floor` puts W on the floor under the board: x along the board's rows of squares, z
# up, the origin under the board's origin corner, the floor at z = 0 (the board's face at z =
# `--board.thickness-m`). The command then checks that the board lies on the floor the photos
# show: the largest nearly horizontal plane of the sparse points must be level with W's floor
# (within 3 degrees and 3 cm), else it stops with one line (a board on a table, a box, a slope).
# With several threads pycolmap's reconstruction differs slightly from run to run (a few
# millimetres here, a few degrees in the closet's pose later); one thread repeats it.

# %%
capture_dir = work / "capture"
nfr_drake("poses", photos, "--out", capture_dir, "--intrinsics", work / "camera.json", "--charuco",
          "--board.square-m", board.square_m, "--board.marker-m", board.marker_m,
          "--board.thickness-m", board.thickness_m, "--world", "floor", "--max-size", SIZE,
          "--sfm.num-threads", 1)  # one thread: the same reconstruction on every run
capture = read_capture_set(capture_dir)
report = json.loads((capture_dir / "report.json").read_text())
X_WO_true = np.linalg.inv(np.array(truth["X_OF"]))  # the closet in the floor frame W
centre_mm, angle_deg = [], []
for frame in capture.frames:
    X_WC_true = X_WO_true @ np.array(truth["X_OC"][report["frames"][f"images/{frame.image_path.name}"]])
    centre_mm.append(1000 * np.linalg.norm(frame.X_OC[:3, 3] - X_WC_true[:3, 3]))
    cos = (np.trace(X_WC_true[:3, :3].T @ frame.X_OC[:3, :3]) - 1) / 2
    angle_deg.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
print(f"camera poses in W against the truth: centres {np.mean(centre_mm):.1f} mm mean "
      f"({np.max(centre_mm):.1f} max), rotations {np.mean(angle_deg):.2f} deg mean")

# %% [markdown]
# ## 3. Fit: masks, the closet's pose, the neural field
# `--estimate-pose` reads the poses as a floor frame. `--masks segmenter` runs the 2D segmenter
# (`models/segmenter`) on each photo; a visual hull of the masks and a box fitted to them give
# X_WO (`nfr_drake/perception/object_pose.py`); the fit runs in that O on the photos painted in
# the training background off the masks (`--room-loss background`: the field's silhouette must
# match the masks), and the result's keypoints and trajectory over q are written in W, with
# X_WO in `extra.object_pose`. The result also says how far to trust it: P(handle within 2 cm),
# calibrated on fits of objects alone (docs/CONFIDENCE.md).

# %%
result_path = work / "result.json"
nfr_drake("infer", capture_dir, "--model", ROOT / "models" / "closet", "--category", "closet",
          "--estimate-pose", "--masks", "segmenter", "--segmenter", ROOT / "models" / "segmenter",
          *FIT, "--threads", 1, "--out", result_path)
result = json.loads(result_path.read_text())
X_WO = np.array(result["extra"]["object_pose"]["X_WO"])
yaw = lambda X: np.degrees(np.arctan2(X[1, 0], X[0, 0]))  # noqa: E731
pose_cm = 100 * np.linalg.norm(X_WO[:2, 3] - X_WO_true[:2, 3])
yaw_deg = (yaw(X_WO) - yaw(X_WO_true) + 180) % 360 - 180
p_true = {k: X_WO_true[:3, :3] @ np.array(v) + X_WO_true[:3, 3] for k, v in truth["keypoints"].items()}
kp_cm = {k: 100 * np.linalg.norm(np.array(result["keypoints"][k]) - p) for k, p in p_true.items()}
print(f"closet pose: {pose_cm:.1f} cm and {yaw_deg:+.1f} deg from the truth; fitted q {result['q']:.2f} "
      "(true 0); keypoints from the truth: " + ", ".join(f"{k} {v:.1f} cm" for k, v in kp_cm.items()))

# %% [markdown]
# The masks (magenta) against the closet's true outline (green), with each photo's IoU. The
# segmenter was trained on rooms like this one but never on this closet or room.

# %%
images = capture.load_images()
masks = object_masks(images, ROOT / "models" / "segmenter")
panels = []
for frame, image, mask in zip(capture.frames, images, masks, strict=True):
    X_OC_true = np.array(truth["X_OC"][report["frames"][f"images/{frame.image_path.name}"]])
    true_mask = scene.render_view(X_OC_true).label > 0
    on = mask > 0.5
    iou = (on & true_mask).sum() / max((on | true_mask).sum(), 1)
    panel = image.astype(float)
    panel[on] = 0.5 * panel[on] + 0.5 * np.array([255.0, 0.0, 255.0])
    panel = np.ascontiguousarray(panel.astype(np.uint8))
    contours, _ = cv2.findContours(true_mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(panel, contours, -1, (0, 255, 0), max(1, SIZE // 400))
    panel = cv2.resize(panel, (256, 192), interpolation=cv2.INTER_AREA)
    cv2.putText(panel, f"IoU {iou:.2f}", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                cv2.LINE_AA)
    panels.append(panel)
save("tutorial_03_masks.png", image_grid([panels[:half], panels[half:2 * half]]))

# %% [markdown]
# The fitted field rendered from each camera at the fitted q, in the estimated O, laid over the
# photo (where the field renders the closet), and the keypoints in the photos: fitted (red:
# the handle and its path as the door opens; blue: the hinge axis) and true (green).

# %%
model, _, _ = load_model(ROOT / "models" / "closet")
z = torch.tensor(result["z"], dtype=torch.float32)
X_OW = np.linalg.inv(X_WO)
overlays, drawn = [], []


def pixel(frame, p):
    """Integer pixel of the point p (3,) in W in the frame's image (OpenCV convention), or None."""
    uv = project(frame, np.asarray(p, float))
    return None if uv is None else tuple(int(round(c - 0.5)) for c in uv)


for frame, image in zip(capture.frames, images, strict=True):
    small = frame.camera.scaled(256, 192)
    view = render_view(model, z, result["q"], small, X_OW @ frame.X_OC)
    photo = cv2.resize(image, (256, 192), interpolation=cv2.INTER_AREA).astype(float)
    on = view.labels > 0
    photo[on] = 0.35 * photo[on] + 0.65 * view.rgb[on]
    overlays.append(photo.astype(np.uint8))

    canvas = np.ascontiguousarray(image.copy())
    thick = max(1, SIZE // 300)
    path = [pixel(frame, p) for p in result["trajectory"]["keypoints"]["handle"]]
    cv2.polylines(canvas, [np.array([p for p in path if p])], False, (255, 60, 60), thick, cv2.LINE_AA)
    fitted = result["keypoints"]
    for a, b, colour in ((fitted["hinge_top"], fitted["hinge_bottom"], (60, 120, 255)),
                         (p_true["hinge_top"], p_true["hinge_bottom"], (0, 220, 0))):
        if pixel(frame, a) and pixel(frame, b):
            cv2.line(canvas, pixel(frame, a), pixel(frame, b), colour, thick, cv2.LINE_AA)
    for p, colour in ((fitted["handle"], (255, 60, 60)), (p_true["handle"], (0, 220, 0))):
        if pixel(frame, p):
            cv2.circle(canvas, pixel(frame, p), 3 * thick, colour, -1, cv2.LINE_AA)
    drawn.append(cv2.resize(canvas, (256, 192), interpolation=cv2.INTER_AREA))
save("tutorial_03_fit.png", image_grid([overlays[:half], overlays[half:2 * half]]))
save("tutorial_03_keypoints.png", image_grid([drawn[:half], drawn[half:2 * half]]))

# %% [markdown]
# Seen from above: the cameras, the board and the closet's footprint, estimated against true.

# %%
def footprint(X, size):
    """The carcass's outline on the floor (5, 2) in W: a rectangle of depth x width about O."""
    d, w = size[0] / 2, size[1] / 2
    corners = np.array([[d, -w], [d, w], [-d, w], [-d, -w], [d, -w]])
    return corners @ X[:2, :2].T + X[:2, 3]


fig, ax = plt.subplots(figsize=(6, 5))
base_lo, base_hi = closet.base_bounds()
for X, size, style, label in ((X_WO_true, base_hi - base_lo, "k-", "closet, true"),
                              (X_WO, result["extra"]["object_pose"]["size"], "m--", "closet, estimated")):
    ax.plot(*footprint(X, size).T, style, lw=2, label=label)
    ax.arrow(*X[:2, 3], *(0.25 * X[:2, 0]), head_width=0.03, color=style[0])  # +x: out of the front
nx, ny = board.squares
ax.add_patch(plt.Rectangle((0, -ny * board.square_m), nx * board.square_m, ny * board.square_m,
                           fc="0.85", ec="0.3", label="board (W's origin at its corner)"))
p_cam = np.array([f.X_OC[:3, 3] for f in capture.frames])
ax.scatter(p_cam[:, 0], p_cam[:, 1], c="tab:blue", s=15, label="cameras, estimated")
ax.set_title(f"closet pose error {pose_cm:.1f} cm, {yaw_deg:+.1f} deg")
ax.set_xlabel("x in W (m)")
ax.set_ylabel("y in W (m)")
ax.set_aspect("equal")
ax.legend(fontsize=8, loc="lower left")
fig.tight_layout()
fig.savefig(out_dir / "tutorial_03_pose.png", dpi=100)
print("wrote", out_dir / "tutorial_03_pose.png")

# %% [markdown]
# ## 4. Plan with the fitted keypoints, simulate on the true closet
# `nfr-drake plan --keypoints result.json` plans with the fit's keypoints, in W: where the
# robot's base stands, the grasp and the door's path all come from them. The object the motion
# is simulated on is the true closet (`--category closet --seed 21`, placed where it stands in
# W): exit status 0 when the door opens, 1 when the simulated motion fails, 2 when no motion is
# found. The replay draws the fitted keypoint paths and the true ones ("keypoints_true").

# %%
replay = work / "open_closet.html"
plan = nfr_drake("plan", "--category", "closet", "--seed", SEED, "--keypoints", result_path,
                 "--object-xyz", *X_WO_true[:3, 3], "--object-yaw-deg", yaw(X_WO_true), "--replay", replay)
print("plan:", "SUCCESS" if plan.returncode == 0 else "the simulated motion failed",
      f"({replay.stat().st_size // 1024} kB replay)")
chromium = shutil.which("chromium") or shutil.which("chromium-browser")
if chromium and not QUICK:  # a still of the replay, 6 s into it, in headless Chromium
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    f"--user-data-dir={work / 'chromium'}", "--enable-unsafe-swiftshader",
                    "--window-size=800,600", "--virtual-time-budget=6000",
                    f"--screenshot={out_dir / 'tutorial_03_replay.png'}", replay.as_uri()],
                   capture_output=True, timeout=300)
    print("wrote", out_dir / "tutorial_03_replay.png")

# %% [markdown]
# ## With real photos
# There is no model of a real closet to simulate on: `--keypoints` alone plans the motion and
# writes its replay (the arm following the plan, the fitted keypoint paths), nothing simulated.
# The keypoints and X_WO in `result.json` are what a robot controller would take.

# %%
nfr_drake("plan", "--keypoints", result_path, "--replay", work / "planned.html")

# %% [markdown]
# Put the board flat on the floor where most photos see it, 10-30 photos around the front of
# the object, each overlapping its neighbours; measure the board's squares and its thickness.
# Check `report.json` (the floor check, the board in each photo), the fit's warnings (a size
# outside the category means the masks or the poses are wrong) and its confidence.

# %%
shutil.rmtree(work)
