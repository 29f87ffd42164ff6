"""A look into an opened compartment: its floor and the free height above the goal from one depth
image.

The keypoints tell where a closet's floor, front and hinge are, not whether it has shelves; a
planner that knows only them must assume the lowest shelf a closet of that height can have
(`nfr_drake.planning.compartment`), which leaves 12-16 cm in the lower closets: too little for a
side-held item and the wrist even where there is no shelf. And the fitted goal's height is off
the floor's by up to a centimetre or two, as much as the held item clears the floor by on its way
in. Once the door is open, a camera held low in front of the compartment sees the floor's top
under the goal and the underside of whatever lies above it (a shelf or the top panel):
`look_into_compartment`.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.objects.articulated import ArticulatedObject
from nfr_drake.planning.compartment import InteriorLook

LOOK_CAMERA = PinholeCamera.from_fov(160, 120, np.radians(90.0))
"""The look's camera: 160 x 120 px, 90 degrees vertical field of view (106 across)."""
LOOK_OUT = 0.12
"""The camera stands this far in front of the front plane, m (nearer than an open door's edge)."""
LOOK_HEIGHT = 0.04
"""The camera's height above the goal (the compartment's floor), m: below any shelf."""
COLUMN_RADIUS = 0.06
"""The column about the goal whose surfaces the look measures, m (horizontal)."""


def look_into_compartment(obj: ArticulatedObject, X_WO: RigidTransform, q: float, goal: np.ndarray,
                          out: np.ndarray, front_distance: float) -> InteriorLook:
    """The floor and the ceiling over `goal` (m, (3,) in W) in `obj` (at X_WO, its fronts at
    articulation q in [0, 1]) as seen from a camera `LOOK_OUT` in front of the front plane
    (`front_distance` m from the goal along `out`, the front's outward horizontal unit normal,
    (3,) in W), `LOOK_HEIGHT` above the goal, looking in level, in the vertical column of radius
    `COLUMN_RADIUS` about the goal: the ceiling is the lowest surface seen above the camera (a
    level camera sees a shelf's underside above itself); when nothing is seen there, the height
    the view reaches at the column's near side (a shelf above it may be there); the floor is the
    median height of the surfaces seen below the camera (the floor's top, seen from above: the
    camera stands over it as long as the goal lies less than `LOOK_HEIGHT` under it), None when
    none is seen."""
    out = np.asarray(out, dtype=float) * [1.0, 1.0, 0.0]
    out = out / np.linalg.norm(out)
    p_WC = np.asarray(goal) + (front_distance + LOOK_OUT) * out + [0.0, 0.0, LOOK_HEIGHT]
    forward = -out
    down = np.array([0.0, 0.0, -1.0])
    right = np.cross(down, forward)
    X_WC = RigidTransform(RotationMatrix(np.column_stack([right, down, forward])), p_WC)
    X_OC = (X_WO.inverse() @ X_WC).GetAsMatrix4()
    depth = ObjectRenderer(obj, LOOK_CAMERA).render(q, X_OC).depth
    cam = LOOK_CAMERA
    v, u = np.nonzero(np.isfinite(depth) & (depth > 0.0) & (depth < 5.0))
    d = depth[v, u]
    p_C = np.stack([(u + 0.5 - cam.cx) / cam.fx * d, (v + 0.5 - cam.cy) / cam.fy * d, d], axis=1)
    p_W = (X_WC.rotation().matrix() @ p_C.T).T + p_WC
    near = np.hypot(*(p_W[:, :2] - np.asarray(goal)[:2]).T) <= COLUMN_RADIUS
    heights = p_W[near, 2]
    above, below = heights[heights > p_WC[2]], heights[heights <= p_WC[2]]
    reach = p_WC[2] + (front_distance + LOOK_OUT - COLUMN_RADIUS) * cam.cy / cam.fy
    return InteriorLook(float(np.median(below)) if below.size else None,
                        float(above.min()) if above.size else float(reach))
