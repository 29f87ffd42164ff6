# %% [markdown]
# # Tutorial 2: from a folder of photos to a capture set with metric poses
#
# The neural-field fit needs photos *with* camera poses, in metres, in the object's frame O
# (docs/CONVENTIONS.md). A phone gives photos without poses. `nfr-drake poses` recovers them:
#
# 1. structure from motion with pycolmap (SIFT on the CPU, exhaustive matching, incremental
#    mapping) gives poses in an arbitrary frame R and scale;
# 2. a ChArUco board in the photos (or known camera centres, `--anchors`) fixes the scale and
#    gives the world frame W: the board's frame B;
# 3. the object's pose in W (`--object-pose`, X_WO) moves everything into O.
#
# Here the "photos" are rendered by Drake, so we know the true poses and can check the result.
# With real photos, start at step 2 with your own folder. Run as plain Python:
# `python tutorials/02_photos_to_capture_set.py` (about half a minute on 2 CPU cores). Figures go
# to `NFR_TUTORIAL_OUT` (default `docs/images`).

# %%
import json
import os
import shutil
import tempfile
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.visualize import image_grid
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.alignment import rotation_angle
from nfr_drake.perception.charuco import CharucoBoardSpec, CharucoPoseEstimator
from nfr_drake.perception.poses import Alignment, estimate_poses
from nfr_drake.perception.synthetic import SyntheticPhotoScene, orbit_poses, write_photo_folder

out_dir = Path(os.environ.get("NFR_TUTORIAL_OUT", "docs/images"))
out_dir.mkdir(parents=True, exist_ok=True)
work = Path(tempfile.mkdtemp(prefix="nfr_tutorial_02_"))

# %% [markdown]
# ## 1. Photos
# A closet (half open, q = 0.5) stands in a room with textured floor and wall: SIFT needs texture,
# and plain furniture has little. A ChArUco board (5 x 7 squares of 8 cm, 6 cm markers,
# DICT_6X6_250) lies on the floor in front of it. Eight photos on an arc in front of the closet,
# through a lens with barrel distortion, as a real camera would take them.

# %%
closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
camera = PinholeCamera.from_fov(800, 600, np.deg2rad(50))
scene = SyntheticPhotoScene(closet, q=0.5, camera=camera)
photos = work / "photos"
write_photo_folder(photos, scene, orbit_poses(8, np.array([0.4, 0.0, 0.35])),
                   distortion=(-0.12, 0.03, 5e-4, -3e-4))
truth = json.loads((photos / "truth.json").read_text())
names = sorted(truth["X_OC"])
thumbs = [cv2.resize(cv2.cvtColor(cv2.imread(str(photos / n)), cv2.COLOR_BGR2RGB), (240, 180),
                     interpolation=cv2.INTER_AREA) for n in names]
sheet = image_grid([thumbs[:4], thumbs[4:]])
cv2.imwrite(str(out_dir / "tutorial_02_photos.png"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
print("wrote", out_dir / "tutorial_02_photos.png")

# %% [markdown]
# ## 2. The board and the camera
# The board's geometry must match the print: measure the squares. OpenCV's detector finds the
# ChArUco corners; with the camera's intrinsics, PnP gives the camera's pose in the board frame
# B (origin at the board's corner, z into the board). Intrinsics go in a JSON file with
# nerfstudio's keys (`fl_x fl_y cx cy w h k1 k2 p1 p2`, pixel centres at +0.5); without one,
# the camera is self-calibrated (SIMPLE_RADIAL: focal length and one distortion term).

# %%
board = CharucoBoardSpec(squares=(5, 7), square_m=0.08, marker_m=0.06, dictionary="DICT_6X6_250")
photo_camera = PinholeCamera.from_json(truth["camera"])
(work / "camera.json").write_text(json.dumps(truth["camera"]))
estimator = CharucoPoseEstimator(board)
bgr = cv2.imread(str(photos / names[2]))
pose = estimator.estimate(bgr, photo_camera)
print(f"{names[2]}: {pose.corners} corners, PnP reprojection error "
      f"{pose.reprojection_error_px:.2f} px, camera {np.linalg.norm(pose.X_BC[:3, 3]):.2f} m "
      "from the board origin")
p_B, uv = estimator.detect(bgr)
X_CB = np.linalg.inv(pose.X_BC)
rvec, tvec = cv2.Rodrigues(X_CB[:3, :3])[0], X_CB[:3, 3]
cv2.drawFrameAxes(bgr, photo_camera.K_opencv, photo_camera.dist_opencv, rvec, tvec, 0.16, 2)
for u, v in uv - 0.5:  # OpenCV's pixel convention for drawing
    cv2.drawMarker(bgr, (round(u), round(v)), (0, 0, 255), cv2.MARKER_CROSS, 7, 1)
(x0, y0), (x1, y1) = (uv.min(axis=0) - 60).astype(int), (uv.max(axis=0) + 60).astype(int)
crop = bgr[max(y0, 0):y1, max(x0, 0):x1]
height = bgr.shape[0] // 2
small = cv2.resize(bgr, (bgr.shape[1] // 2, height), interpolation=cv2.INTER_AREA)
zoom = cv2.resize(crop, (round(crop.shape[1] * height / crop.shape[0]), height),
                  interpolation=cv2.INTER_AREA)
cv2.imwrite(str(out_dir / "tutorial_02_board.png"), np.hstack([small, zoom]))
print("wrote", out_dir / "tutorial_02_board.png")

# %% [markdown]
# In the figure the red crosses are the detected ChArUco corners (here 9 of 24: the board is
# small and seen at a slant) and the axes show the board frame B: x red, y green, z blue (into
# the floor).

# %% [markdown]
# ## 3. Poses
# The object frame O sits on the floor under the closet; we measured where the board lies
# relative to it, i.e. X_OB, so X_WO = X_BO = inverse(X_OB). On the command line this step is
#
# ```
# nfr-drake poses photos/ --out capture/ --intrinsics camera.json --charuco \
#     --board.square-m 0.08 --board.marker-m 0.06 --object-pose X_BO.json
# ```
#
# where X_BO.json holds the 4x4 matrix (or pass `--object-pose="x y z roll pitch yaw"`).

# %%
X_BO = np.linalg.inv(np.array(truth["X_OB"]))
capture_dir = work / "capture"
report = estimate_poses(photos, capture_dir, Alignment(charuco=board), photo_camera, X_WO=X_BO)
print(report.summary())

# %% [markdown]
# ## 4. Check against the truth
# The capture set is an ordinary one: `read_capture_set` validates it. Its images are
# undistorted (pinhole), and `points3D.ply` holds the sparse points in O. Compare the estimated
# camera poses with the ones Drake rendered from.

# %%
capture = read_capture_set(capture_dir)
p_est, p_true = [], []
for frame in capture.frames:
    X_true = np.array(truth["X_OC"][report.frames[f"images/{frame.image_path.name}"]])
    p_est.append(frame.X_OC[:3, 3])
    p_true.append(X_true[:3, 3])
    error_mm = 1000 * np.linalg.norm(frame.X_OC[:3, 3] - X_true[:3, 3])
    error_deg = np.degrees(rotation_angle(X_true[:3, :3].T @ frame.X_OC[:3, :3]))
    print(f"{frame.image_path.name}: centre error {error_mm:.1f} mm, rotation error {error_deg:.2f} deg")
p_est, p_true = np.array(p_est), np.array(p_true)
assert np.linalg.norm(p_est - p_true, axis=1).max() < 0.02

ply = (capture_dir / "points3D.ply").read_text().splitlines()
points = np.array([[float(v) for v in line.split()[:3]] for line in ply[ply.index("end_header") + 1:]])
fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
for ax, (i, j), title in zip(axes, [(0, 1), (0, 2)], ["top view (x, y)", "side view (x, z)"],
                             strict=True):
    near = np.abs(points).max(axis=1) < 3.0
    ax.scatter(points[near, i], points[near, j], s=0.5, c="0.6", label="sparse points")
    ax.scatter(p_true[:, i], p_true[:, j], s=80, facecolors="none", edgecolors="k",
               label="true cameras")
    ax.scatter(p_est[:, i], p_est[:, j], s=12, c="tab:red", label="estimated cameras")
    keypoints = np.array(list(truth["keypoints"].values()))
    ax.scatter(keypoints[:, i], keypoints[:, j], s=20, c="tab:blue", marker="x",
               label="closet keypoints")
    ax.set_title(title)
    ax.set_xlabel("xyz"[i] + " in O (m)")
    ax.set_ylabel("xyz"[j] + " in O (m)")
    ax.set_aspect("equal")
axes[0].legend(loc="lower left", fontsize=8)
fig.tight_layout()
fig.savefig(out_dir / "tutorial_02_poses.png", dpi=100)
print("wrote", out_dir / "tutorial_02_poses.png")

# %% [markdown]
# ## 5. Next: fit the closet
# The capture set is what the neural-field fit reads: `nfr-drake infer capture/ --category closet
# --out result.json` (being built; see issue 7's note). Tips for real photos: 10-30 photos around
# the front of the object, each overlapping its neighbours, the board visible in at least two
# (more is better), no zoom between shots, sharp images; check `report.json` for unregistered
# photos and the alignment residuals.

# %%
shutil.rmtree(work)
