"""Parsing works under any DRAKE_ALLOW_NETWORK and never knows a remote package."""

import os
import subprocess
import sys

import pytest

from nfr_drake.parsing import NETWORK_VARIABLE, PACKAGE_NAME, REMOTE_PACKAGES

SCRIPT = f"""
import os
from pydrake.multibody.plant import MultibodyPlant
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.parsing import make_parser
from nfr_drake.world.robot import add_floor, add_panda

before = os.environ.get("{NETWORK_VARIABLE}")
plant = MultibodyPlant(0.0)
add_panda(plant)
add_floor(plant)
add_articulated_object(plant, sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 0)))
plant.Finalize()
names = make_parser(MultibodyPlant(0.0)).package_map().GetPackageNames()
assert os.environ.get("{NETWORK_VARIABLE}") == before, "the variable was not restored"
print("packages", sorted(names), "bodies", plant.num_bodies())
"""


@pytest.mark.parametrize("allow", [None, "meshcat", "none", "meshcat:package_map"])
def test_models_load_under_any_network_setting(allow):
    env = {k: v for k, v in os.environ.items() if k != NETWORK_VARIABLE}
    if allow is not None:
        env[NETWORK_VARIABLE] = allow
    run = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert PACKAGE_NAME in run.stdout and not any(p in run.stdout for p in REMOTE_PACKAGES)
