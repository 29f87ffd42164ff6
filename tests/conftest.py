"""Test-wide settings: no network downloads (Meshcat still runs), CPU-sized torch threads."""

import os

os.environ.setdefault("DRAKE_ALLOW_NETWORK", "meshcat")
