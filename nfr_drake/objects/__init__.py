"""Articulated object categories: parameter sampling, SDFormat, keypoints, semantic labels."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects.articulated import (
    SEMANTIC_CLASS_NAMES,
    ArticulatedObject,
    Front,
    Part,
    SemanticClass,
    part_index_of,
    part_semantic_class,
)
from nfr_drake.objects.closet import sample_closet
from nfr_drake.objects.drawer import sample_drawer
from nfr_drake.objects.furniture import sample_furniture
from nfr_drake.objects.sdformat import to_sdformat

CATEGORIES: dict[str, Callable[..., ArticulatedObject]] = {
    "closet": sample_closet,
    "drawer": sample_drawer,
    "furniture": sample_furniture,
}

# Seed domains keep the random streams of training data, capture sets and anything else disjoint:
# object i of seed s in domain d is drawn from np.random.default_rng([d, s, i]).
SEED_DOMAIN_TRAIN = 0
SEED_DOMAIN_CAPTURE = 1
SEED_DOMAIN_ROOM = 2


def object_rng(domain: int, seed: int, index: int) -> np.random.Generator:
    """The random stream of one object; streams of different (domain, seed, index) are independent."""
    return np.random.default_rng([domain, seed, index])


def sample_object(category: str, rng: np.random.Generator, name: str | None = None
                  ) -> ArticulatedObject:
    """Draw one object of `category` ("closet", "drawer" or "furniture")."""
    if category not in CATEGORIES:
        raise NfrDrakeError(f"unknown category {category!r}; choose one of {sorted(CATEGORIES)}")
    return CATEGORIES[category](rng, name=name or category)


__all__ = [
    "CATEGORIES",
    "SEED_DOMAIN_CAPTURE",
    "SEED_DOMAIN_ROOM",
    "SEED_DOMAIN_TRAIN",
    "SEMANTIC_CLASS_NAMES",
    "ArticulatedObject",
    "Front",
    "Part",
    "SemanticClass",
    "object_rng",
    "part_index_of",
    "part_semantic_class",
    "sample_object",
    "to_sdformat",
]
