"""SDFormat 1.9 text of an `ArticulatedObject`: two links, one joint, visuals and collisions.

The carcass is not welded here: whoever loads the model welds `carcass` to the world at X_WO.
"""

from __future__ import annotations

from xml.sax.saxutils import escape

import numpy as np

from nfr_drake.objects.articulated import ArticulatedObject, Part

# Effort and velocity limits of the object's joint; generous, the arm is what limits motion.
_JOINT_EFFORT = 100.0
_JOINT_VELOCITY = 10.0
_CARCASS_MASS_KG = 20.0


def _vec(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in v)


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
    return (
        f'      <visual name="{name}">{pose}<geometry>{geom}</geometry>'
        f"<material><diffuse>{rgba}</diffuse><ambient>{rgba}</ambient></material></visual>\n"
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


def to_sdformat(obj: ArticulatedObject) -> str:
    """The object as an SDFormat string that Drake's Parser loads as one model instance."""
    mass, p_Mcm, inertia = obj.moving_inertia()
    carcass_inertia = np.eye(3) * _CARCASS_MASS_KG * obj.height**2 / 12.0
    base = "".join(_part_elements(p) for p in obj.base_parts)
    moving = "".join(_part_elements(p) for p in obj.moving_parts)
    lower, upper = 0.0, obj.joint_upper
    return f"""<?xml version="1.0"?>
<sdf version="1.9">
  <model name="{escape(obj.name)}">
    <link name="{obj.base_link_name}">
{_inertial(_CARCASS_MASS_KG, (0, 0, obj.height / 2), carcass_inertia)}{base}    </link>
    <link name="{obj.moving_link_name}">
      <pose>{_vec(obj.p_OJ)} 0 0 0</pose>
{_inertial(mass, p_Mcm, inertia)}{moving}    </link>
    <joint name="{obj.joint_name}" type="{obj.joint_type}">
      <parent>{obj.base_link_name}</parent>
      <child>{obj.moving_link_name}</child>
      <axis>
        <xyz>{_vec(obj.axis_O)}</xyz>
        <limit><lower>{lower:.6g}</lower><upper>{upper:.6g}</upper>
          <effort>{_JOINT_EFFORT}</effort><velocity>{_JOINT_VELOCITY}</velocity></limit>
        <dynamics><damping>{obj.joint_damping:.6g}</damping></dynamics>
      </axis>
    </joint>
  </model>
</sdf>
"""
