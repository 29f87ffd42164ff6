#!/usr/bin/env bash
# The main job: Drake cameras photograph an unseen closet, the shipped neural field is fitted (the
# default fit, the fast preset) and forward-simulated, the planner opens the door with those
# keypoints, the arm is simulated on the true closet and an HTML replay is written.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${NFR_DEMO_OUT:-out/demo}
.venv/bin/nfr-drake demo --model models/closet --replay "$out/open_closet.html" "$@"
