"""SDFormat 1.9 text of an `ArticulatedObject`: the carcass link, one link and joint per front.

The carcass is not welded here: whoever loads the model welds `carcass` to the world at X_WO.
"""

from __future__ import annotations

from xml.sax.saxutils import escape

import numpy as np

from nfr_drake.objects.articulated import ArticulatedObject, Front, Part

# Effort and velocity limits of the object's joint; generous, the arm is what limits motion.
_JOINT_EFFORT = 100.0
_JOINT_VELOCITY = 10.0
_CARCASS_MASS_KG = 20.0


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def _geometry(part: Part) -> str:
    if part.shape == "box":
        return f"<box><size>{_vec(part.size)}</size></box>"
    if part.shape == "cylinder":
        r, length = part.size
        return f"<cylinder><radius>{r:.6g}</radius><length>{length:.6g}</length></cylinder>"
    return f"<sphere><radius>{part.size[0]:.6g}</radius></sphere>"


def _part_elements(part: Part) -> str:
    pose = f"<pose>{_vec(part.p_LP)} {_vec(part.rpy_LP)}</pose>"
    geom = _geometry(part)
    rgba = _vec(part.rgba)
    name = escape(part.geometry_name)
    texture = "" if part.texture is None else f"<drake:diffuse_map>{escape(part.texture)}</drake:diffuse_map>"
    return (
        f'      <visual name="{name}">{pose}<geometry>{geom}</geometry>'
        f"<material><diffuse>{rgba}</diffuse><ambient>{rgba}</ambient>{texture}</material></visual>\n"
        f'      <collision name="{name}">{pose}<geometry>{geom}</geometry></collision>\n'
    )


def _inertial(mass: float, p_cm, inertia: np.ndarray) -> str:
    i = inertia
    return (
        f"      <inertial><pose>{_vec(p_cm)} 0 0 0</pose><mass>{mass:.6g}</mass><inertia>"
        f"<ixx>{i[0, 0]:.6g}</ixx><ixy>{i[0, 1]:.6g}</ixy><ixz>{i[0, 2]:.6g}</ixz>"
        f"<iyy>{i[1, 1]:.6g}</iyy><iyz>{i[1, 2]:.6g}</iyz><izz>{i[2, 2]:.6g}</izz>"
        f"</inertia></inertial>\n"
    )


def _front_elements(obj: ArticulatedObject, front: Front) -> str:
    mass, p_Mcm, inertia = front.inertia()
    parts = "".join(_part_elements(p) for p in front.parts)
    return f"""    <link name="{front.link_name}">
      <pose>{_vec(front.p_OJ)} 0 0 0</pose>
{_inertial(mass, p_Mcm, inertia)}{parts}    </link>
    <joint name="{front.joint_name}" type="{front.joint_type}">
      <parent>{obj.base_link_name}</parent>
      <child>{front.link_name}</child>
      <axis>
        <xyz>{_vec(front.axis_O)}</xyz>
        <limit><lower>0</lower><upper>{front.joint_upper:.9g}</upper>
          <effort>{_JOINT_EFFORT}</effort><velocity>{_JOINT_VELOCITY}</velocity></limit>
        <dynamics><damping>{front.damping:.6g}</damping></dynamics>
      </axis>
    </joint>
"""


def to_sdformat(obj: ArticulatedObject) -> str:
    """The object as an SDFormat string that Drake's Parser loads as one model instance."""
    carcass_inertia = np.eye(3) * _CARCASS_MASS_KG * obj.height**2 / 12.0
    base = "".join(_part_elements(p) for p in obj.base_parts)
    fronts = "".join(_front_elements(obj, f) for f in obj.fronts)
    return f"""<?xml version="1.0"?>
<sdf version="1.9" xmlns:drake="http://drake.mit.edu">
  <model name="{escape(obj.name)}">
    <link name="{obj.base_link_name}">
{_inertial(_CARCASS_MASS_KG, (0, 0, obj.height / 2), carcass_inertia)}{base}    </link>
{fronts}  </model>
</sdf>
"""
