"""What one pose-estimation run did: registered photos, reprojection error, alignment, timings."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

from nfr_drake.perception.alignment import AlignmentResult


@dataclass
class PoseReport:
    """Summary of `estimate_poses`, written as `report.json` beside transforms.json.

    registered / unregistered: photo names; frames: capture-set file path -> photo name;
    mean_reprojection_error_px: over all observations of the sparse model (working-size pixels);
    calibration: "known", "self-calibrated" or "self-calibrated from the EXIF focal length";
    cameras: the photos' intrinsics as used (nerfstudio keys + distortion, working size);
    board_poses: photo name -> ChArUco corners and PnP reprojection error, with --charuco;
    floor: with --world floor, the floor plane of the sparse points (`floor.FloorPlane.to_json`);
    seconds: wall time per stage.
    """

    photos: int
    working_size_px: int
    registered: list[str]
    unregistered: list[str]
    mean_reprojection_error_px: float
    points3D: int
    num_models: int
    calibration: str
    alignment: AlignmentResult | None
    frame: str
    frames: dict[str, str] = field(default_factory=dict)
    cameras: dict[str, dict] = field(default_factory=dict)
    board_poses: dict[str, dict] = field(default_factory=dict)
    floor: dict | None = None
    seconds: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        d["alignment"] = self.alignment.to_json() if self.alignment else None
        return d

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=2)

    def summary(self) -> str:
        """A few human-readable lines (degrees and millimetres)."""
        lines = [f"registered {len(self.registered)} of {self.photos} photos"
                 + (f"; not registered: {', '.join(self.unregistered)}" if self.unregistered else ""),
                 f"sparse model: {self.points3D} points, mean reprojection error "
                 f"{self.mean_reprojection_error_px:.3f} px at {self.working_size_px} px; "
                 f"intrinsics {self.calibration}"]
        if self.alignment is None:
            lines.append("no metric alignment: poses are in the reconstruction's arbitrary frame "
                         "and scale")
        else:
            a = self.alignment
            res = a.position_residuals_m.values()
            line = (f"alignment ({a.method}, {len(a.position_residuals_m)} images): scale "
                    f"{a.similarity.scale:.5g} m/unit, camera-centre residual rms "
                    f"{1000 * a.rms_position_m:.1f} mm, max {1000 * max(res):.1f} mm")
            if a.rotation_residuals_rad:
                line += f", rotation max {math.degrees(max(a.rotation_residuals_rad.values())):.2f} deg"
            lines.append(line)
        if self.floor is not None:
            f = self.floor
            lines.append(f"floor: {f['support']} of {f['points']} sparse points on a plane tilted "
                         f"{f['tilt_deg']:.2f} deg, {100 * f['height_m']:+.1f} cm from z = 0" if f["found"]
                         else "floor: no plane in the sparse points to check the board against")
        lines.append(f"poses are in frame {self.frame}; stages: "
                     + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()))
        return "\n".join(lines)
