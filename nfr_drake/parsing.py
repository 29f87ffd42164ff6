"""Drake parsers that resolve `package://nfr_drake/...` to `sdf/` and know no remote package.

Drake's default package map registers the remote package `drake_models`; with networking for
package maps turned off (`DRAKE_ALLOW_NETWORK` set without `package_map`, as offline users do) and
an empty download cache, that registration, and so every `Parser()` and `RobotDiagramBuilder()`,
fails. `make_parser` and `make_robot_diagram_builder` let the registration happen, then remove the
remote package: they work under any value of the variable and never download anything.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.planning import RobotDiagramBuilder

import nfr_drake
from nfr_drake.errors import NfrDrakeError

PACKAGE_NAME = "nfr_drake"
REMOTE_PACKAGES = ("drake_models",)
"""The packages Drake's default package map fetches over the network."""
NETWORK_VARIABLE = "DRAKE_ALLOW_NETWORK"


def sdf_dir() -> Path:
    """The `sdf/` folder beside the package source (the package is installed editable)."""
    path = Path(nfr_drake.__file__).resolve().parent.parent / "sdf"
    if not (path / "package.xml").is_file():
        raise NfrDrakeError(
            f"robot models not found at {path}; install nfr-drake editable from its source tree "
            "(pip install -e .) so that sdf/ sits beside the nfr_drake package")
    return path


@contextmanager
def _remote_registration_allowed():
    """`DRAKE_ALLOW_NETWORK` with `package_map` added, while Drake builds its default package
    map (registering a remote package downloads nothing)."""
    old = os.environ.get(NETWORK_VARIABLE)
    if old is None or "package_map" in old.split(":"):
        yield
        return
    os.environ[NETWORK_VARIABLE] = "package_map" if old in ("", "none") else f"{old}:package_map"
    try:
        yield
    finally:
        os.environ[NETWORK_VARIABLE] = old


def _own_packages(parser: Parser) -> Parser:
    """`parser` with the remote packages removed and `nfr_drake` added."""
    package_map = parser.package_map()
    for name in REMOTE_PACKAGES:
        if package_map.Contains(name):
            package_map.Remove(name)
    package_map.Add(PACKAGE_NAME, str(sdf_dir()))
    return parser


def make_parser(plant: MultibodyPlant, model_name_prefix: str = "") -> Parser:
    """A Parser adding models to `plant` (names prefixed by `model_name_prefix`), with the
    `nfr_drake` package and without remote packages."""
    with _remote_registration_allowed():
        return _own_packages(Parser(plant, model_name_prefix))


def make_robot_diagram_builder(time_step: float) -> RobotDiagramBuilder:
    """A RobotDiagramBuilder whose parser has the `nfr_drake` package and no remote package."""
    with _remote_registration_allowed():
        builder = RobotDiagramBuilder(time_step=time_step)
    _own_packages(builder.parser())
    return builder
