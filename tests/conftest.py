"""Test-wide settings.

Network: nothing in nfr-drake may download (drake_models included). DRAKE_ALLOW_NETWORK=meshcat
alone would be the strictest setting, but in drake 1.51 it makes every `Parser()` constructor
fail, because the default PackageMap registers the remote `drake_models` package and refuses to
do so with package_map networking off and an empty download cache. We therefore also allow
`package_map`; since this machine (and CI) cannot reach GitHub, any accidental use of
`package://drake_models/...` still fails the test that makes it.
"""

import os

import pytest

os.environ.setdefault("DRAKE_ALLOW_NETWORK", "meshcat:package_map")


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """2 closets x 2 articulations x 4 views at 32 px, rendered by Drake (a few seconds)."""
    from nfr_drake.data.generate import generate_command

    out = tmp_path_factory.mktemp("nfr_data") / "closets"
    generate_command(category="closet", objects=2, out=out, articulations=2, views=4, size=32,
                     workers=1)
    return out
