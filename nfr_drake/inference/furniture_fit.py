"""Fitting a furniture field (several articulation slots) to posed images, and what it gives.

The networks stay frozen; z = [z_art (2 per slot), z_obj] moves by Adam on the image loss plus
SRN's latent prior (`FurnitureFitConfig`), each slot's z_art reflected onto the upper half of its
circle after every step (as `nfr_drake.inference.fit` does: the networks were trained there only,
and a slot left below is rendered at another articulation than the q reported and swept).
Starts: `starts` training codes (evenly spaced over the code table) with every slot shut and with
every slot half open are scored by one forward pass on `lookup_rays` rays; the best `keep` are
fitted together, and the lowest image loss wins. Each slot of the result has its q (its own
z_art), the keypoint head's existence and type logits and its four keypoints; forward simulation
sweeps one slot's q with the others held (`part_trajectory`).
docs/NEURAL_FIELD.md, "Furniture: several parts".

Handles seen by the 2D handle detector (`handles`, M points in O triangulated across the views,
`nfr_drake.perception.handle_triangulation.locate_handles`) join the fit three ways: the piece
has M fronts, so slots 0..M-1 exist (slot k is front k; `count_from_handles`); the starts are the
training codes whose keypoint head lays its handles out as the sightings (`HandleTerm` on every
training code shut and half open, then the image loss on the best `starts`); and the same term
joins the loss of every step and the choice of the winner. The term pairs the M sightings one
to one with slots 0..M-1 (`handle_pairing`: "order", sighting k with slot k once the sightings
are put in the fronts' canonical order, `sighting_order`; "nearest", the assignment of least
summed squared distance to the head's handles, redone at each step) and adds
w log(1 + d^2 / s^2) per pair, averaged: robust as the closets' sighting term. After
the fit, each matched slot is translated onto its sighting (`snap_to_handles`): its keypoints and
its swept path move rigidly by the sighting minus the head's handle, so the head gives the part's
layout (hinge and goal about the handle, the way it moves) and the sighting where it is; the doors
of a pair are hinged on their outer sides (`pair_hinges`); where the detector read the front
behind a sighting (`nfr_drake.perception.front_reading`), its type, a door's hinge points and the
goal's place come from that front (`place_fronts`); and each part moves as a rigid front on its
joint (`slot_path`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS, slot_part, slot_trajectory
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import ObservedRays
from nfr_drake.inference.forward import keypoint_trajectory
from nfr_drake.nfr.latent import slots_q_to_z_art, split_z, z_art_to_q
from nfr_drake.nfr.losses import latent_loss
from nfr_drake.nfr.model import NFRModel
from nfr_drake.objects.fronts import DOOR_OPENING, MAX_BOX_DEPTH, TRAVEL_FRACTION
from nfr_drake.perception.front_reading import (
    SightedFront,
    face_turn,
    face_width,
    handle_offset,
    handle_turn,
    hinge_points,
    shut_edges,
)


@dataclass(frozen=True)
class FurnitureFitConfig:
    """Options of the furniture fit."""

    starts: int = 16
    """Training codes looked up as starts (each with all slots shut and all half open)."""
    lookup_rays: int = 1024
    """Rays (edge-weighted as the steps') on which the lookup scores the start codes."""
    keep: int = 2
    """Best looked-up starts fitted together; the lowest image loss wins."""
    steps: int = 150
    """Adam steps."""
    rays_per_step: int = 512
    """Random pixels (over all views) per step, shared by the starts."""
    detail_fraction: float = 0.5
    """Share of each step's rays drawn where the image has edges (handles, gaps between fronts)."""
    lr: float = 1e-2
    """Adam learning rate of z."""
    latent_weight: float = 1e-3
    """SRN's prior on z_obj (mean of squares), as in training."""
    seed: int = 0
    """Seed of the ray draws."""
    handle_weight: float = 2e-3
    """Weight w of the handle term (module docstring; 0: the sighted handles are not in the loss
    nor in the choice of starts)."""
    handle_scale_m: float = 0.015
    """s of the handle term, m: about the sightings' accuracy."""
    count_from_handles: bool = True
    """With M >= 1 sighted handles, slots 0..M-1 exist and no others (else the head's logits)."""
    handle_detector: bool = True
    """Sight the handles with the model's 2D handle detector when it ships one (`infer_parts`)."""
    handle_pairing: str = "order"
    """How sightings pair with slots (module docstring): "order" or "nearest"."""
    column_gap_m: float = 0.2
    """`sighting_order`: handles closer than this in y share a column, m."""
    snap_to_handles: bool = True
    """Translate each slot matched with a sighted handle onto it (module docstring; `FurnitureFit.shift`)."""
    pair_gap_m: float = 0.25
    """`pair_hinges`: a door's sighted handle with another level one closer than this in y is one
    of a pair, hinged on the side away from it, m (0: the head's hinge side always)."""
    read_fronts: bool = True
    """Take each sighted front's type, a door's hinge points and the goal's place from what the
    detector read of the fronts, where it read them (`place_fronts`; with the "order" pairing
    only)."""
    head_type_weight: float = 0.1
    """`place_fronts`: the weight of the keypoint head's door margin (door logit minus drawer
    logit, about -12 to 12) added to the read door probability's log-odds (0: the read type
    alone)."""
    pair_type_log_odds: tuple[float, float] = (3.4, -0.4)
    """`place_fronts`: what being one of a pair (`pair_sides`) or not adds to a read front's door
    log-odds: the generator's log-likelihood ratios, door against drawer (`python
    benchmarks/handle_layout.py`: in a pair 163 of 538 doors and 7 of 728 drawers, +3.45 and -0.35;
    on 2000 pieces of seed 7 +3.43 and -0.39); (0, 0): not weighed."""
    travel_from_depth: bool = True
    """A drawer slot paired with a sighting travels as far as the carcass depth its handle implies
    (`depth_travel`), not as far as the keypoint head says (`drawer_travel`)."""
    travel_depth_share: float = 0.75
    """`depth_travel`: a drawer's travel as a share of the carcass depth (with `handle_standoff_m`
    chosen among 0.7, 0.75, 0.8 and 3, 4, 5 cm on the clean calibration captures' drawers;
    docs/FURNITURE.md, "How far a drawer slides")."""
    handle_standoff_m: float = 0.04
    """`depth_travel`: how far a shut drawer's handle stands in front of the carcass, m."""
    drawer_goal_below_handle_m: float = 0.056
    """`drawer_goal`: how far a drawer's box floor (its goal) lies below its handle, m: the
    generator's median (`python benchmarks/handle_layout.py`: over the 728 drawers of 400 pieces of
    seed 123, p10-p90 0.026-0.131; with `handle_standoff_m` and the true travel, `drawer_goal`'s
    x is 1.2 cm in front of the true goal's, median)."""
    read_turn_min_deg: float = 15.0
    """`place_fronts`: a read door whose face (`face_turn`) and handle about its hinge
    (`handle_turn`) have both turned more than this from shut, degrees, takes the handle's turn
    as its q (inf: the field's q always; docs/FURNITURE.md, "A door's opening from its read
    face")."""
    offset_edges: tuple[float, ...] = (0.1, 0.5)
    """`place_fronts`: bins of where a handle sits across its read face (`handle_offset`: 0 in the
    middle, 1 at a vertical edge), between these edges."""
    offset_type_log_odds: tuple[float, ...] = (-0.9, -0.3, 2.6)
    """`place_fronts`: what each bin of `offset_edges` adds to the door log-odds of a read front
    that is not one of a pair (a pair's two faces can be read as one wide face, whose middle lies
    between their handles): one value per bin, zeros: not weighed. A drawer's pull sits in its
    middle, a door's handle by its free edge; read faces are a few cm off, so the bins overlap:
    the log-likelihood ratios, door against drawer, of the read offsets of the development
    pipeline's photos (`python benchmarks/furniture_pipeline_sightings.py --seed 901`: lone doors
    23 / 31 / 51 of 105, drawers 121 / 88 / 8 of 217; -0.93, -0.32, +2.58)."""

    def __post_init__(self):
        if min(self.starts, self.lookup_rays, self.keep, self.steps, self.rays_per_step) < 1:
            raise ConfigError("FurnitureFitConfig: starts, lookup_rays, keep, steps and "
                              "rays_per_step must be at least 1")
        if not 0.0 <= self.detail_fraction <= 1.0 or self.lr <= 0 or self.latent_weight < 0:
            raise ConfigError("FurnitureFitConfig: detail_fraction in [0, 1], lr > 0, "
                              "latent_weight >= 0")
        if not 0.0 < self.travel_depth_share <= 1.0 or self.handle_standoff_m < 0:
            raise ConfigError("FurnitureFitConfig: travel_depth_share in (0, 1], handle_standoff_m >= 0")
        if self.handle_weight < 0 or self.handle_scale_m <= 0:
            raise ConfigError("FurnitureFitConfig: handle_weight >= 0, handle_scale_m > 0")
        if self.handle_pairing not in ("order", "nearest") or min(self.column_gap_m, self.pair_gap_m) < 0:
            raise ConfigError("FurnitureFitConfig: handle_pairing is \"order\" or \"nearest\", "
                              "column_gap_m and pair_gap_m >= 0")
        if (len(self.offset_type_log_odds) != len(self.offset_edges) + 1
                or np.any(np.diff(self.offset_edges) <= 0)):
            raise ConfigError("FurnitureFitConfig: offset_type_log_odds needs one value per bin of "
                              "offset_edges (one more than the edges, which increase)")


@dataclass
class FurnitureFit:
    """The fitted code z (2 S + k,); per slot q (S,), exists bool (S,) (existence logit > 0),
    types (S,) index into PART_TYPES, keypoints (S, 4, 3) in O (`SLOT_KEYPOINTS`): the head's
    moved by shift (S, 3) in O, m (a slot's translation onto its sighted handle; zero if none),
    a pair's doors hinged outward (`pair_hinges`); image_loss
    (MSE on the last step's rays), steps, seconds of wall time; travel (S,) how far each slot
    slides as a drawer over q in [0, 1], m (`drawer_travel`, or `depth_travel` for a paired slot
    with `FurnitureFitConfig.travel_from_depth`); handles (M, 3) the sighted handles
    in O the fit used (M = 0: none), handle_order (M,) their indices among the handles given to
    `fit_furniture` (handle k of the fit is the given handle handle_order[k]); the starts fitted
    together (`keep` of them): their final codes start_z (keep, 2 S + k) and image losses on the
    last step's rays start_losses (keep,); z is the one of the lowest loss."""

    z: torch.Tensor
    q: np.ndarray
    exists: np.ndarray
    types: np.ndarray
    keypoints: np.ndarray
    shift: np.ndarray
    image_loss: float
    steps: int
    seconds: float
    travel: np.ndarray
    handles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    handle_order: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    start_z: torch.Tensor | None = None
    start_losses: np.ndarray | None = None


class HandleTerm:
    """The handle term (module docstring) of codes against sighted handles p_O (M, 3) in O:
    slots 0..M-1 of the keypoint head paired one to one with the sightings, sighting k with slot
    k (`in_order`) or by least summed squared distance."""

    def __init__(self, model: NFRModel, handles_O, weight: float, scale_m: float, in_order: bool = False):
        self.model, self.weight, self.scale, self.in_order = model, weight, scale_m, in_order
        self.handles = torch.as_tensor(np.asarray(handles_O, np.float32).reshape(-1, 3))
        self.handle_index = SLOT_KEYPOINTS.index("handle")

    def __call__(self, z: torch.Tensor) -> torch.Tensor:
        """The term (B,) of codes z (B, D); zeros without sightings or weight."""
        M = len(self.handles)
        if M == 0 or self.weight == 0:
            return z.new_zeros(len(z))
        S = self.model.config.num_slots
        slots = self.model.keypoints(z).view(len(z), S, len(SLOT_KEYPOINTS), 3)[:, :M, self.handle_index]
        d2 = ((slots[:, :, None] - self.handles.to(z)[None, None]) ** 2).sum(-1)  # (B, slot, sighting)
        if self.in_order:
            return self.weight * torch.log1p(d2.diagonal(dim1=1, dim2=2) / self.scale ** 2).mean(-1)
        cost = d2.detach().cpu().numpy()
        pairs = torch.tensor(np.array([linear_sum_assignment(c) for c in cost]), dtype=torch.long)
        matched = d2[torch.arange(len(z))[:, None], pairs[:, 0], pairs[:, 1]]
        return self.weight * torch.log1p(matched / self.scale ** 2).mean(-1)


def image_mse(model: NFRModel, z: torch.Tensor, rays: ObservedRays, index: torch.Tensor) -> torch.Tensor:
    """Image MSE (B,) of codes z (B, D) on the rays `index`."""
    r, rgb = rays.take(index, z.shape[0])
    return ((model.render(z, r, logits=False).rgb - rgb) ** 2).mean(dim=(1, 2))


def start_codes(z_obj: torch.Tensor, S: int) -> torch.Tensor:
    """Codes (2 N, D) of z_obj (N, k) with every slot shut, then every slot half open."""
    return torch.cat([torch.cat([slots_q_to_z_art(torch.full((len(z_obj), S), q), S).to(z_obj),
                                 z_obj], -1) for q in (0.0, 0.5)])


def fit_furniture(model: NFRModel, rays: ObservedRays, codes: torch.Tensor,
                  config: FurnitureFitConfig = FurnitureFitConfig(),
                  handles_O: np.ndarray | None = None,
                  fronts: list[SightedFront | None] | None = None) -> FurnitureFit:
    """Fit z of a model with several slots to the observed rays of a capture; codes (N, k) are
    the training codes the starts come from; handles_O (M, 3) in O, m: handles sighted by the
    handle detector (module docstring), or None; fronts (M,): what the detector read of each
    one's front (`nfr_drake.perception.front_reading`; None where it read nothing), or None."""
    S = model.config.num_slots
    if S < 2:
        raise ConfigError("fit_furniture needs a model with several articulation slots")
    t0 = time.perf_counter()
    generator = torch.Generator().manual_seed(config.seed)
    handles = np.zeros((0, 3)) if handles_O is None else np.asarray(handles_O, float).reshape(-1, 3)
    if fronts is not None and len(fronts) != len(handles):
        raise ConfigError(f"fit_furniture: {len(fronts)} fronts for {len(handles)} handles")
    in_order = config.handle_pairing == "order"
    if fronts is None or not config.read_fronts or not in_order:
        fronts = [None] * len(handles)
    order = (sighting_order(handles, config.column_gap_m, fronts=fronts) if in_order
             else np.arange(len(handles)))
    handles, fronts, order = handles[order][:S], [fronts[i] for i in order][:S], order[:S]
    term = HandleTerm(model, handles, config.handle_weight, config.handle_scale_m, in_order)
    if len(handles) and config.handle_weight > 0:  # the training codes laid out as the sightings
        with torch.no_grad():
            every = start_codes(codes.to(rays.rgb), S)
            cands = every[term(every).argsort()[:2 * config.starts]]
    else:
        pick = torch.linspace(0, len(codes) - 1, min(config.starts, len(codes))).round().long()
        cands = start_codes(codes[pick].to(rays.rgb), S)
    with torch.no_grad():
        index = rays.sample(config.lookup_rays, config.detail_fraction, generator)
        loss = image_mse(model, cands, rays, index) + term(cands)
    z = cands[loss.argsort()[:config.keep]].clone().requires_grad_(True)
    optimiser = torch.optim.Adam([z], lr=config.lr)
    for _ in range(config.steps):
        index = rays.sample(config.rays_per_step, config.detail_fraction, generator)
        per_code = image_mse(model, z, rays, index)
        total = (per_code.sum() + term(z).sum()
                 + config.latent_weight * latent_loss(split_z(z, S)[1]) * len(z))
        optimiser.zero_grad(set_to_none=True)
        total.backward()
        optimiser.step()
        with torch.no_grad():  # every slot's z_art on the upper half circle, where q lies
            z[:, 1:2 * S:2].abs_()
    with torch.no_grad():
        best = int((per_code + term(z)).argmin())
        z_best = z[best].detach()
        logits = model.slot_logits(z_best[None])[0]
        keypoints = model.keypoints(z_best[None])[0].view(S, len(SLOT_KEYPOINTS), 3)
        q = z_art_to_q(split_z(z_best, S)[0].view(S, 2))
    exists = (logits[:, 0] > 0).cpu().numpy()
    if len(handles) and config.count_from_handles:
        exists = np.arange(S) < len(handles)
    keypoints = keypoints.double().cpu().numpy()
    shift = np.zeros((S, 3))
    if config.snap_to_handles:
        shift = handle_shift(keypoints[:, SLOT_KEYPOINTS.index("handle")], handles, in_order)
    types = logits[:, 1:].argmax(-1).cpu().numpy()
    placed = pair_hinges(keypoints + shift[:, None], types, len(handles), config.pair_gap_m)
    sides, middles = np.zeros(S), np.full(S, np.nan)
    middles[:len(handles)] = pair_middles(handles, config.pair_gap_m)
    sides[:len(handles)] = pair_sides(handles, config.pair_gap_m, middles=middles[:len(handles)])
    q = q.double().cpu().numpy()
    handle = SLOT_KEYPOINTS.index("handle")
    travel = np.array([depth_travel(placed[k, handle, 0], q[k], config.travel_depth_share,
                                    config.handle_standoff_m)
                       if config.travel_from_depth and k < len(handles) else drawer_travel(model, z_best, k)
                       for k in range(S)])
    if any(f is not None for f in fronts):
        margin = (logits[:, 1] - logits[:, 2]).cpu().numpy()  # door minus drawer (PART_TYPES)
        placed, types, q = place_fronts(placed, types, q, travel, fronts, sides, margin, config, middles)
    return FurnitureFit(z_best, q, exists, types, placed, shift,
                        float(per_code[best].detach()), config.steps, time.perf_counter() - t0, travel,
                        handles, order, z.detach().clone(), per_code.detach().double().cpu().numpy())


def read_door_log_odds(front: SightedFront, paired: bool, pair_log_odds: tuple[float, float],
                       offset_log_odds: tuple[tuple[float, ...], tuple[float, ...]]) -> float:
    """The log-odds that a read front is a door, by what the detector read and where its handle is:
    the read door probability's log-odds, plus pair_log_odds[0] for one of a pair (`paired`) or
    pair_log_odds[1] for one not, plus for one not the value of offset_log_odds[1] in the bin of
    offset_log_odds[0] (edges) its `handle_offset` falls in (a pair's two faces can be read as one
    wide face, whose middle lies between their handles)."""
    p = float(np.clip(front.door_probability, 1e-6, 1.0 - 1e-6))
    log_odds = np.log(p / (1.0 - p)) + (pair_log_odds[0] if paired else pair_log_odds[1])
    if not paired:
        edges, odds = offset_log_odds
        log_odds += odds[int(np.searchsorted(edges, handle_offset(front), side="right"))]
    return float(log_odds)


COMPARTMENT_MIDDLE_X = 0.0
"""A door's goal x in O, m: the middle of its compartment's depth. A compartment spans the
carcass's depth, and O lies under the middle of the carcass's footprint (docs/CONVENTIONS.md), so
its middle is x = 0 (the back panel moves it 4 mm in the generator). The head's goal, moved with
the slot onto its sighted handle, carries the handle's error in x (an open door's handle is far
in front of the carcass; docs/FURNITURE.md, "Where the goal lies")."""


def place_fronts(keypoints: np.ndarray, types: np.ndarray, q: np.ndarray, travel: list[float],
                 fronts: list[SightedFront | None], sides: np.ndarray, door_margin: np.ndarray,
                 config: FurnitureFitConfig, pair_middle_y: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slot keypoints (S, 4, 3) in O, types (S,) and q (S,) with what the detector read of each
    paired slot's front (fronts[k] for slot k; None: the field's): its type (a door where
    `read_door_log_odds` with the config's pair and offset odds, one of a pair where sides[k] !=
    0, plus `head_type_weight` times the keypoint head's door margin, door_margin (S,) its door
    logit minus its drawer logit, is positive); a door's hinge points on its face's edge away
    from the handle, or for one of a pair (sides[k] != 0, `pair_sides`: a pair can be read as one
    wide face) on the edge away from its neighbour (`hinge_points`); a door's goal (the
    compartment floor behind it) at `COMPARTMENT_MIDDLE_X` in x (the depth is not on the face),
    its face's bottom edge in z (the floor lies 1-4 cm above that edge, a panel: not read) and its
    shut face's middle in y, or for a shut door of a pair halfway between its hinge edge and
    pair_middle_y[k] ((S,), where the pair meets, NaN: not one of a pair; a wide face's middle is
    where the pair meets); a drawer's goal at `drawer_goal` (its box floor, which moves with it:
    placed from the handle, not from the read face's bottom edge, which is read 3.5-9 cm too low,
    median); a drawer the head took for a door gets a pull line through its handle along O's +x,
    `travel[k]` long (m), shut at q[k] (the field's q, (S,)).
    A door's q is the field's unless both its read face (`face_turn`) and its handle about its
    read hinge (`handle_turn`) have turned more than `read_turn_min_deg`; then it is the handle's
    turn: the field's q is right on shut doors and often far off on open ones, the handle's turn
    is a few degrees off, and a shut door read ajar would be opened short by as much (a face alone
    is read up to 27 degrees ajar on shut doors)."""
    out, types, q = keypoints.copy(), types.copy(), np.array(q, float)
    h, g, a0, a1 = (SLOT_KEYPOINTS.index(n) for n in ("handle", "goal", "axis_0", "axis_1"))
    offset_log_odds = (config.offset_edges, config.offset_type_log_odds)
    for k, front in enumerate(fronts[:len(out)]):
        if front is None:
            continue
        door = (read_door_log_odds(front, sides[k] != 0, config.pair_type_log_odds, offset_log_odds)
                + config.head_type_weight * float(door_margin[k]) > 0.0)
        if door:
            left, _ = shut_edges(front)
            middle = left + face_width(front) / 2
            out[k, [a0, a1]] = hinge_points(front, None if sides[k] == 0 else sides[k] > 0)
            types[k] = PART_TYPES.index("door")
            turn = handle_turn(front, out[k, [a0, a1]])
            if min(face_turn(front), turn) > np.radians(config.read_turn_min_deg):
                q[k] = turn / DOOR_OPENING
            elif pair_middle_y is not None and np.isfinite(pair_middle_y[k]):
                middle = (out[k, a0, 1] + pair_middle_y[k]) / 2
            out[k, g] = COMPARTMENT_MIDDLE_X, middle, front.corners[2:, 2].mean()
            continue
        out[k, g] = drawer_goal(out[k, h], travel[k], config.handle_standoff_m,
                                config.drawer_goal_below_handle_m)
        if PART_TYPES[int(types[k])] == "door":
            out[k, a0] = out[k, h] - [q[k] * travel[k], 0.0, 0.0]
            out[k, a1] = out[k, a0] + [travel[k], 0.0, 0.0]
        types[k] = PART_TYPES.index("drawer")
    return out, types, q


def drawer_goal(handle: np.ndarray, travel: float, standoff_m: float, below_m: float) -> np.ndarray:
    """A drawer's goal (3,) in O, m, the middle of its box's floor, from its handle (3,) in O at any
    opening and its travel (m): under the handle in y (a pull sits at its front's middle),
    `below_m` under it in z, and half the box's depth behind the front in x: the front stands
    `standoff_m` behind the handle and a box `TRAVEL_FRACTION` of whose depth is the travel lies
    behind it (the travel's depth is the carcass's, `depth_travel`)."""
    return np.asarray(handle, float) - [standoff_m + travel / (2.0 * TRAVEL_FRACTION), 0.0, below_m]


def handle_shift(slot_handles: np.ndarray, handles: np.ndarray, in_order: bool = False) -> np.ndarray:
    """Per slot, the translation (S, 3), m, that puts its handle (slot_handles (S, 3) in O) on the
    sighted handle (handles (M, 3) in O, M <= S) paired with it as `HandleTerm` pairs them
    (sighting k with slot k when `in_order`, else least summed squared distance); zero for the
    other slots."""
    shift = np.zeros_like(slot_handles)
    M = len(handles)
    if in_order:
        shift[:M] = handles - slot_handles[:M]
    elif M:
        slots, sights = linear_sum_assignment(((slot_handles[:M, None] - handles[None]) ** 2).sum(-1))
        shift[slots] = handles[sights] - slot_handles[slots]
    return shift


def pair_middles(handles: np.ndarray, pair_gap_m: float, level_m: float = 0.05) -> np.ndarray:
    """Per sighted handle (M, 3) in O, m, the y (M,) halfway between it and the nearest other
    handle within `level_m` in height and `pair_gap_m` in y (where a pair's doors meet), NaN
    where there is none: a door with such a neighbour is one of a pair, whose doors hinge on the
    edges away from each other (their handles near where they meet;
    `benchmarks/handle_layout.py` measures the rule)."""
    middles = np.full(len(handles), np.nan)
    for k in range(len(handles)):
        dy, dz = handles[:, 1] - handles[k, 1], handles[:, 2] - handles[k, 2]
        near = np.flatnonzero((np.abs(dz) < level_m) & (np.abs(dy) < pair_gap_m)
                              & (np.arange(len(handles)) != k))
        if near.size:
            middles[k] = handles[k, 1] + dy[near[np.argmin(np.abs(dy[near]))]] / 2.0
    return middles


def pair_sides(handles: np.ndarray, pair_gap_m: float, level_m: float = 0.05,
               middles: np.ndarray | None = None) -> np.ndarray:
    """Per sighted handle (M, 3) in O, m, the side (+1: +y, -1: -y) of its pair's other handle,
    0 where it is not one of a pair; from `pair_middles` (computed when not given)."""
    if middles is None:
        middles = pair_middles(handles, pair_gap_m, level_m)
    return np.nan_to_num(np.sign(middles - np.asarray(handles, float).reshape(-1, 3)[:, 1]))


def pair_hinges(keypoints: np.ndarray, types: np.ndarray, sighted: int, pair_gap_m: float) -> np.ndarray:
    """Slot keypoints (S, 4, 3) in O with the hinge of each door of a pair on its outer side: a
    slot k < `sighted` (its handle a sighting) typed door with a neighbour (`pair_sides`) whose
    head puts its hinge on the neighbour's side gets its hinge points and goal mirrored in y
    about its handle; the other doors keep the head's side."""
    out = keypoints.copy()
    h, g, a0, a1 = (SLOT_KEYPOINTS.index(n) for n in ("handle", "goal", "axis_0", "axis_1"))
    sighted = min(sighted, len(keypoints))
    sides = pair_sides(keypoints[:sighted, h], pair_gap_m)
    for k in range(sighted):
        if PART_TYPES[int(types[k])] != "door" or sides[k] == 0:
            continue
        if np.sign(keypoints[k, [a0, a1], 1].mean() - keypoints[k, h, 1]) == sides[k]:
            for i in (g, a0, a1):
                out[k, i, 1] = 2.0 * keypoints[k, h, 1] - keypoints[k, i, 1]
    return out


def sighting_order(handles_O: np.ndarray, column_gap_m: float, level_m: float = 0.03,
                   fronts: list[SightedFront | None] | None = None,
                   edge_m: float = 0.04, centred_m: float = 0.03, half_level_m: float = 0.15) -> np.ndarray:
    """Indices (M,) that put handles (M, 3) in O, m, in the order of their fronts as far as the
    handles tell it (the fronts' canonical order, `nfr_drake.objects.furniture.canonical_order`:
    by panel left edge, then top edge): columns left to right (by their leftmost handle's y;
    handles less than `column_gap_m` apart in y share one, and so do handles whose read fronts,
    fronts (M,) where given (None: not read), have their shut left edges (`shut_edges`) and
    right edges (one `face_width` further) within `edge_m`: stacked doors with their handles on
    opposite sides; a face read as wide as two fronts shares one edge only), in a column top to
    bottom, handles within `level_m` in height left to right (a pair's doors, side by side
    drawers); a cell's right half goes after the column's other fronts, a right half being the
    right one of two handles of one cell (within `half_level_m` in height) with a third handle of
    the column within `centred_m` in y of their middle (`right_halves_last`; either 0: none). A
    door's handle lies near its free edge, not its left one, so without read fronts some layouts
    come out in another order than the fronts'."""
    M = len(handles_O)
    column = np.arange(M)  # a union-find forest: each handle's parent

    def root(i: int) -> int:
        while column[i] != i:
            i = column[i]
        return i

    by_y = np.argsort(handles_O[:, 1], kind="stable")
    for a, b in zip(by_y[:-1], by_y[1:], strict=True):
        if handles_O[b, 1] - handles_O[a, 1] < column_gap_m:
            column[root(b)] = root(a)
    spans = [None if f is None else shut_edges(f)[0] + np.array([0.0, face_width(f)])
             for f in (fronts or [None] * M)]
    for a in range(M):
        for b in range(a + 1, M):
            if spans[a] is not None and spans[b] is not None and np.all(np.abs(spans[a] - spans[b]) < edge_m):
                column[root(b)] = root(a)
    columns: dict[int, list[int]] = {}
    for i in by_y:
        columns.setdefault(root(i), []).append(int(i))
    order = []
    for members in columns.values():  # in the order of their leftmost handles
        members = sorted(members, key=lambda j: -handles_O[j, 2])
        for a in range(1, len(members)):  # insertion: a level neighbour further left goes first
            b = a
            while (b > 0 and abs(handles_O[members[b], 2] - handles_O[members[b - 1], 2]) < level_m
                   and handles_O[members[b], 1] < handles_O[members[b - 1], 1]):
                members[b - 1], members[b] = members[b], members[b - 1]
                b -= 1
        order += right_halves_last(handles_O, members, centred_m, half_level_m)
    return np.array(order, int)


def right_halves_last(handles_O: np.ndarray, column: list[int], centred_m: float, half_level_m: float,
                      half_gap_m: float = 0.05) -> list[int]:
    """One column's handle indices (into handles_O (M, 3) in O, m) top to bottom, with each right
    half moved after the others (in their order): a handle with another one at least
    `half_gap_m` to its left in y and within `half_level_m` in height (one cell: side by side
    drawers' pulls are level, a pair's doors put their handles at their own heights, 0.9-1.1 m
    in the generator), and a third handle of the column within `centred_m` in y of the two's
    middle (a full-width drawer's pull centred under or over the split). The right half's left
    edge, the column's middle, puts it after every front of the column that starts at the
    column's left edge (`nfr_drake.objects.furniture.canonical_order`). `sighting_order`'s
    `half_level_m` was chosen among 0.03, 0.1, 0.15 and 0.2 m on the development pipeline's
    photos (docs/FURNITURE.md, "Sightings in the fronts' order")."""
    y, z = handles_O[:, 1], handles_O[:, 2]

    def right_half(j: int) -> bool:
        return any(abs(z[k] - z[j]) < half_level_m and y[k] < y[j] - half_gap_m
                   and any(abs(y[m] - (y[j] + y[k]) / 2) < centred_m for m in column if m not in (j, k))
                   for k in column if k != j)

    halves = [j for j in column if right_half(j)]
    return [j for j in column if j not in halves] + halves


def part_trajectory(model: NFRModel, z: torch.Tensor, slot: int, q_grid: np.ndarray) -> np.ndarray:
    """Forward simulation of one part by the keypoint head: slot `slot`'s keypoints (N, 4, 3) in O
    as its q sweeps q_grid (N,), the other slots held at their q in z (what the fit gives:
    `slot_path`)."""
    path = keypoint_trajectory(model, z, q_grid, slot)
    return path.reshape(len(path), model.config.num_slots, len(SLOT_KEYPOINTS), 3)[:, slot]


def drawer_travel(model: NFRModel, z: torch.Tensor, slot: int) -> float:
    """A drawer's travel over q in [0, 1] as the keypoint head gives slot `slot` at code z, m: its
    handle's displacement along O's +x (where that is not forward, the displacement's length: a
    drawer's path is never degenerate)."""
    ends = part_trajectory(model, z, slot, np.array([0.0, 1.0]))[:, SLOT_KEYPOINTS.index("handle")]
    travel = float(ends[1, 0] - ends[0, 0])
    return travel if travel > 0.0 else float(np.linalg.norm(ends[1] - ends[0]))


MAX_TRAVEL_M = TRAVEL_FRACTION * MAX_BOX_DEPTH
"""The longest drawer travel of the training world, m (`depth_travel`'s cap)."""


def depth_travel(handle_x: float, q: float, share: float, standoff_m: float) -> float:
    """A drawer's travel over q in [0, 1], m, from the carcass depth its handle implies: O lies
    under the middle of the carcass's footprint (docs/CONVENTIONS.md), so a carcass whose front
    is at x_f is 2 x_f deep; the shut handle stands `standoff_m` in front of it and the drawer,
    at q, `q` times the travel T further, T being `share` of the depth: T = 2 share (x - s - q T),
    x the handle's x in O (m) at q; capped to 5 cm .. `MAX_TRAVEL_M` (docs/FURNITURE.md, "How
    far a drawer slides")."""
    travel = 2.0 * share * (handle_x - standoff_m) / (1.0 + 2.0 * share * q)
    return float(np.clip(travel, 0.05, MAX_TRAVEL_M))


def slot_path(model: NFRModel, fit: FurnitureFit, slot: int, q_grid: np.ndarray) -> np.ndarray:
    """Slot `slot`'s keypoints (N, 4, 3) in O along q_grid (N,) as the fit gives them, from where
    the fit put them at its q (`FurnitureFit.keypoints`), moved as a rigid front on the joint its
    type names: a drawer slides straight along O's +x (the front's normal, docs/CONVENTIONS.md),
    its handle and goal by the fit's travel (`FurnitureFit.travel`); a door's
    handle turns about the line through its hinge points, 90 degrees over q in [0, 1], outward
    (`slot_trajectory`). The head's own sweep (`part_trajectory`) bends a drawer sideways and
    stops it short near the end of its travel, which jams a drawer pulled along it, and turns a
    door by other angles than its q says (docs/FURNITURE.md)."""
    if PART_TYPES[int(fit.types[slot])] == "drawer":
        path = np.repeat(fit.keypoints[slot][None], len(q_grid), axis=0)
        handle, goal = SLOT_KEYPOINTS.index("handle"), SLOT_KEYPOINTS.index("goal")
        path[:, [handle, goal], 0] += ((np.asarray(q_grid, float) - fit.q[slot]) * fit.travel[slot])[:, None]
    else:
        path = slot_trajectory("door", fit.keypoints[slot], fit.q[slot], q_grid)
    return path


def part_json(model: NFRModel, fit: FurnitureFit, slot: int, q_grid: np.ndarray) -> dict:
    """Slot `slot` of a fit as a part (`slot_part`) at the fitted q, its path `slot_path` over
    q_grid (N,)."""
    return slot_part(slot, fit.types[slot], fit.q[slot], fit.keypoints[slot], q_grid,
                     slot_path(model, fit, slot, q_grid))


def parts_json(model: NFRModel, fit: FurnitureFit, q_grid: np.ndarray) -> list[dict]:
    """`parts: [{index, type, q, keypoints, trajectory}]` (`part_json`) of the slots the head says
    exist."""
    return [part_json(model, fit, int(k), q_grid) for k in np.flatnonzero(fit.exists)]
