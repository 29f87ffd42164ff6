"""Run one scenario: perception with the neural field (or the object's true keypoints), planning,
simulation.

Usage: python systems/run_scenario.py systems/open_closet.yaml [--replay out/x.html]
Exit status 0 when the simulated task succeeds, 1 when it fails, 2 on bad input or when the fit
is refused (its confidence below the threshold; one line says why, nothing is planned).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nfr_drake.errors import NfrDrakeError
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", type=Path, help="scenario YAML (see systems/*.yaml)")
    parser.add_argument("--replay", help="HTML replay path (overrides the scenario's)")
    args = parser.parse_args()
    try:
        scenario = Scenario.load(args.scenario)
        if args.replay is not None:
            scenario.replay = args.replay
        outcome = run_scenario(scenario)
    except NfrDrakeError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(outcome.report())
    if outcome.refused:
        return 2
    return 0 if outcome.task.success else 1


if __name__ == "__main__":
    sys.exit(main())
