"""Whose handle each slot gets: the handle detector's sightings on the pipeline's own photos of
shut furniture, in the order the fit pairs them with slots, against the true fronts.

Usage: python benchmarks/furniture_pipeline_sightings.py [--seed 200] [--objects 0 1 ...]
       [--csv-path F] [--min-share 0.5] [--loose-share 0.6] [--loose-rms-px 1.2] [--merged-px 4]
       [--behind-m 0.05] [--half-levels 0 0.03 0.1 0.15 0.2] [--no-bars] [--no-bar-points]
For each piece of `nfr-drake eval-pipeline --category furniture` (the same seed, piece and part
to open, `object_scenario`), its perception cameras photograph it shut
(`pipeline.perception_photos`), the model's detector sights the handles and reads their fronts
(`locate_handles`, `read_front`) and the fit's `sighting_order` puts them in slot order. A
sighting is a front's when within `--cm` of its true handle; how many doors and drawers are
sighted. Each piece's part to open is then:
"right" (slot k has front k's handle), or why not, first that applies: "part unsighted" (no
sighting is the part's), "extra sighting" (a sighting is no front's), "other unsighted" (another
front has none: later slots shift), "order" (every front sighted once, in another order); the
same for the orders of other `--half-levels` (`sighting_order`'s half_level_m, side by side:
how far in height two handles may be one split cell's), and how far behind all the other
points a front's point and a point of no front lie at most (`in_front`). Also the read type
(door or drawer) of every matched sighting against its front's, and how many views agree with
the sightings of fronts and of no front, and how closely (RMS, px at 128 px; the
triangulation's loose-point rule, `FURNITURE_LOOSE`, is set by --loose-share and --loose-rms-px,
0 and inf: off); and, for each front no triangulated handle is within `--cm` of, in how many
views the detector's handle probability exceeds 0.5 on its handle's pixels (the piece rendered
with its labels from the same cameras: the detector found it there) and in how many one of the
views' own sightings lies within 2 px (at 128 px) of its handle's projection (its votes point
at its grip centre): in 3 or more, the detector saw it and the triangulation lost it; and what
its grip is
(`lost_grip`: a knob, one of a pair or not; a long bar, with a triangulated point on it or not;
a shorter bar). Then, for the matched sightings
of fronts that are not one of a pair (`pair_sides`), where the handle sits across its read face
(`handle_offset`, in the bins of `FurnitureFitConfig.offset_edges`): doors and drawers per bin
and the log-likelihood ratio, door against drawer (`FurnitureFitConfig.offset_type_log_odds`
is chosen from this on the development seed 901); and the read types as the fit takes them
(the read door probability's log-odds plus the pair's odds, `pair_type_log_odds`, and the
offset's, `--offset-log-odds`; the keypoint head's margin left out): how many are wrong, with
and without the offset's odds. Nothing is fitted.
"""

from __future__ import annotations

import argparse
import platform
from collections import Counter
from datetime import date
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import CaptureFrame
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.inference.furniture_fit import (
    FurnitureFitConfig,
    pair_sides,
    read_door_log_odds,
    sighting_order,
)
from nfr_drake.jsonio import write_rows_csv
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.front_reading import SightedFront, handle_offset, read_front
from nfr_drake.perception.handle_detector.model import DETECTOR_DIR, load_detector
from nfr_drake.perception.handle_triangulation import (
    FURNITURE_BAR_SHARE,
    FURNITURE_BEHIND_M,
    FURNITURE_LOOSE,
    FURNITURE_MERGED_PX,
    FURNITURE_MIN_SHARE,
    locate_handles,
    project,
    sightings,
)
from nfr_drake.systems.pipeline import perception_photos
from nfr_drake.systems.scenario import Scenario

OUTCOMES = ("right", "part unsighted", "extra sighting", "other unsighted", "order")


def piece_outcome(true_handles: np.ndarray, sighted: np.ndarray, part: int, cm: float
                  ) -> tuple[str, list[int]]:
    """The part's outcome (`OUTCOMES`, module docstring) and, per sighting in slot order
    (sighted (M, 3) in O), the index of the true front whose handle (true_handles (N, 3)) it is,
    -1 for none within `cm`."""
    owner = []
    for p in sighted:
        d = np.linalg.norm(true_handles - p, axis=1)
        owner.append(int(d.argmin()) if d.min() < cm / 100.0 else -1)
    if part < len(owner) and owner[part] == part:
        return "right", owner
    if part not in owner:
        return "part unsighted", owner
    if -1 in owner:
        return "extra sighting", owner
    if len(set(owner)) < len(true_handles):
        return "other unsighted", owner
    return "order", owner


def print_order_variants(variants: dict[float, list[tuple[str, list[int]]]], fronts: list[int]) -> None:
    """Per `sighting_order` half_level_m (variants: per piece its `piece_outcome`; fronts: per
    piece its number of fronts): the part to open paired with its own handle, and of the pieces
    whose fronts were each sighted once, those in the fronts' order."""
    if not variants:
        return
    print("\n| half_level_m (m) | the part to open right | fronts each sighted once | in the fronts' order |"
          "\n|---|---|---|---|")
    for level, outcomes in variants.items():
        once = [owner for (_, owner), n in zip(outcomes, fronts, strict=True)
                if sorted(owner) == list(range(n))]
        print(f"| {level:.2f} | {sum(o == 'right' for o, _ in outcomes)} | {len(once)} | "
              f"{sum(owner == sorted(owner) for owner in once)} |")


LOST_GRIPS = ("knob, one of a pair", "knob", "long bar, a point on it", "long bar", "shorter bar")
"""`lost_grip`'s classes."""
LONG_BAR_M = 0.3
"""A bar at least this long is a long one, m."""
PAIR_M = 0.12
"""A knob with another front's handle within this is one of a pair, m."""


def lost_grip(grip_half_length: float, true_handles: np.ndarray, k: int, handles: np.ndarray) -> str:
    """The grip of front k (true handles (N, 3) in O) that no triangulated handle (handles (M, 3)
    in O) is within `--cm` of, as one of `LOST_GRIPS`: a knob (no length), one of a pair when
    another front's handle is within `PAIR_M`; a long bar (`LONG_BAR_M`), with a triangulated
    point on it when one lies within its half length of its middle; a shorter bar."""
    if grip_half_length == 0.0:
        others = np.linalg.norm(np.delete(true_handles, k, axis=0) - true_handles[k], axis=1)
        return LOST_GRIPS[0] if np.any(others < PAIR_M) else LOST_GRIPS[1]
    if 2 * grip_half_length >= LONG_BAR_M:
        on_it = np.any(np.linalg.norm(handles - true_handles[k], axis=1) <= grip_half_length)
        return LOST_GRIPS[2] if on_it else LOST_GRIPS[3]
    return LOST_GRIPS[4]


def views_seeing(frames: list[CaptureFrame], found: list, p_O: np.ndarray, px: float = 2.0) -> int:
    """In how many of the frames one of the sightings `found` (`HandleSighting`s) lies within `px`
    (at 128 px) of the projection of p_O (3,) in O."""
    seen = 0
    for f, frame in enumerate(frames):
        uv = project(frame, p_O)
        if uv is None:
            continue
        near = [np.linalg.norm(s.uv - uv) * 128.0 / frame.camera.height for s in found if s.frame == f]
        seen += bool(near) and min(near) <= px
    return seen


def views_detecting(maps: list, views: list, front: int) -> int:
    """In how many of the views (`RenderedView`s of the photos' cameras) the detector's handle
    probability (`HandleMap`s, one per view) exceeds 0.5 on a pixel of the front's handle label:
    the detector found the handle there, whatever its votes say of where the grip centre is."""
    return sum(bool((m.probability[(v.label == int(SemanticClass.HANDLE)) & (v.part == front)] > 0.5).any())
               for m, v in zip(maps, views, strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=Path("models/furniture"))
    parser.add_argument("--seed", type=int, default=200)
    parser.add_argument("--objects", type=int, nargs="+", default=list(range(100)))
    parser.add_argument("--cm", type=float, default=5.0,
                        help="a sighting within this of a true handle is that front's")
    parser.add_argument("--csv-path", type=Path)
    parser.add_argument("--behind-m", type=float, default=FURNITURE_BEHIND_M,
                        help="points this far behind every other one are left out (`in_front`; "
                             "inf: none), m")
    parser.add_argument("--half-levels", type=float, nargs="*", default=[0.0, 0.03, 0.1, 0.15, 0.2],
                        help="sighting_order's half_level_m values compared side by side (0: no "
                             "split cell's right half moved), m")
    parser.add_argument("--min-share", type=float, default=FURNITURE_MIN_SHARE,
                        help="the share of the views a point projects into that must agree on it")
    parser.add_argument("--loose-share", type=float, default=FURNITURE_LOOSE[0])
    parser.add_argument("--loose-rms-px", type=float, default=FURNITURE_LOOSE[1])
    parser.add_argument("--merged-px", type=float, default=FURNITURE_MERGED_PX,
                        help="triangulate_handles' merged_px (0: every view counts in a point's share)")
    parser.add_argument("--no-bars", action="store_true",
                        help="without the views' bar segments: no upright bars the points leave unexplained "
                             "(`triangulate_bars`), and two points close in every view are one "
                             "handle whether or not they lie on one bar")
    parser.add_argument("--no-bar-points", action="store_true",
                        help="a bar's views are its segments' only, not the point sightings on it "
                             "(`triangulate_bars`' points)")
    parser.add_argument("--bar-share", type=float, default=FURNITURE_BAR_SHARE,
                        help="triangulate_bars' min_share")
    parser.add_argument("--offset-log-odds", type=float, nargs="+",
                        default=list(FurnitureFitConfig.offset_type_log_odds))
    args = parser.parse_args()
    torch.set_num_threads(1)
    base = Scenario(category="furniture", model=str(args.model), seed=args.seed)
    detector, _ = load_detector(args.model / DETECTOR_DIR)
    config = FurnitureFitConfig(offset_type_log_odds=tuple(args.offset_log_odds))
    gap = config.column_gap_m
    typed: list[tuple[str, SightedFront, bool]] = []  # per matched sighting: kind, read front, paired
    rows, types, sighted_kinds, kinds = [], Counter(), Counter(), Counter()
    agreement: dict[bool, list[tuple[int, float]]] = {True: [], False: []}  # a front's: (views, RMS px)
    # per unsighted front: (views detecting its pixels, views with a sighting on its grip centre)
    unsighted_views: dict[str, list[tuple[int, int]]] = {"door": [], "drawer": []}
    lost_grips: list[str] = []  # per unsighted front, `lost_grip`
    variants: dict[float, list[tuple[str, list[int]]]] = {level: [] for level in args.half_levels}
    behind: dict[bool, list[float]] = {True: [], False: []}  # of a front's point / of no front's, m
    for index in args.objects:
        scenario = object_scenario(base, index)
        obj = scenario.sample_object()
        images, X_WCs, cameras = perception_photos(scenario)
        X_OW = np.linalg.inv(scenario.X_WO.GetAsMatrix4())
        frames = [CaptureFrame(Path(f"camera_{i}"), X_OW @ X_WC, camera)
                  for i, (X_WC, camera) in enumerate(zip(X_WCs, cameras, strict=True))]
        handle_maps = detector.detect(images)
        found = [s for i, m in enumerate(handle_maps) for s in sightings(m, i)]
        handles = locate_handles(handle_maps, frames, min_share=args.min_share, bars=not args.no_bars,
                                 loose=(args.loose_share, args.loose_rms_px), merged_px=args.merged_px,
                                 bar_share=args.bar_share, behind_m=args.behind_m,
                                 bar_points=not args.no_bar_points)
        maps = detector.read_fronts(images)
        fronts = [read_front(h, maps, frames) for h in handles]
        points = np.array([h.p_O for h in handles]).reshape(-1, 3)
        order = sighting_order(points, gap, fronts=fronts)
        sighted = np.array([handles[i].p_O for i in order]).reshape(-1, 3)
        truth = np.array([f.keypoints(0.0)["handle"] for f in obj.fronts])
        outcome, owner = piece_outcome(truth, sighted, scenario.part, args.cm)
        for level in args.half_levels:  # the same sightings in the order each variant gives
            variant = points[sighting_order(points, gap, fronts=fronts, half_level_m=level)]
            variants[level].append(piece_outcome(truth, variant, scenario.part, args.cm))
        kinds.update(f.kind for f in obj.fronts)
        sighted_kinds.update(obj.fronts[k].kind for k in set(owner) - {-1})
        lost = sorted(set(range(len(truth))) - set(owner))
        labelled = []
        if lost:
            renderer = ObjectRenderer(obj, cameras[0])
            labelled = [renderer.render(0.0, f.X_OC) for f in frames]
        for k in lost:
            unsighted_views[obj.fronts[k].kind].append(
                (views_detecting(handle_maps, labelled, k), views_seeing(frames, found, truth[k])))
            lost_grips.append(lost_grip(obj.fronts[k].grip_half_length, truth, k,
                                        np.array([h.p_O for h in handles]).reshape(-1, 3)))
        if len(sighted) >= 3:  # how far each point lies behind all the others (`in_front`)
            for i, k in enumerate(owner):
                behind[k >= 0].append(float(np.delete(sighted[:, 0], i).min() - sighted[i, 0]))
        sides = pair_sides(sighted, config.pair_gap_m)
        for i, k, side in zip(order, owner, sides, strict=True):
            rms_128 = handles[i].rms_px * 128.0 / frames[0].camera.height
            agreement[k >= 0].append((len(handles[i].views), rms_128))
            if k >= 0:
                read = "unread" if fronts[i] is None else ("door" if fronts[i].is_door else "drawer")
                types[(obj.fronts[k].kind, read)] += 1
                if fronts[i] is not None:
                    typed.append((obj.fronts[k].kind, fronts[i], side != 0))
        rows.append({"index": index, "part": scenario.part, "part_type": obj.fronts[scenario.part].kind,
                     "fronts": len(truth), "sightings": len(sighted), "outcome": outcome,
                     "sighted_fronts": len(set(owner) - {-1}), "owners": " ".join(map(str, owner))})
        print(f"{index}: part {scenario.part} of {len(truth)}, {len(sighted)} sightings of fronts "
              f"{owner}: {outcome}", flush=True)
    print(f"\n{date.today()}, {platform.machine()}, {args.model}, seed {args.seed}, {len(rows)} pieces, "
          f"a sighting within {args.cm} cm")
    print("| the part to open | pieces | doors | drawers |\n|---|---|---|---|")
    for outcome in OUTCOMES:
        these = [r for r in rows if r["outcome"] == outcome]
        print(f"| {outcome} | {len(these)} | {sum(r['part_type'] == 'door' for r in these)} "
              f"| {sum(r['part_type'] == 'drawer' for r in these)} |")
    print_order_variants(variants, [r["fronts"] for r in rows])
    print("\nthe furthest a point lies behind all the others (pieces with 3+ points): "
          + ", ".join(f"of {name} {100 * max(behind[own], default=float('nan')):.1f} cm"
                      for own, name in ((True, "a front"), (False, "no front"))))
    owners = [int(k) for r in rows for k in r["owners"].split()]
    print(f"\nfronts sighted {sum(r['sighted_fronts'] for r in rows)} of {sum(r['fronts'] for r in rows)} "
          f"(doors {sighted_kinds['door']} of {kinds['door']}, drawers {sighted_kinds['drawer']} of "
          f"{kinds['drawer']}); "
          f"sightings {len(owners)}, of no front {owners.count(-1)}; read types of the fronts' "
          "sightings: " + ", ".join(f"{kind} read {read} {n}" for (kind, read), n in sorted(types.items())))
    print("\n| sightings | how many | agreeing views: 3-5 | 6-7 | 8-10 | RMS, median (px at 128 px) |"
          "\n|---|---|---|---|---|---|")
    for own, name in ((True, "of a front"), (False, "of no front")):
        views = np.array([v for v, _ in agreement[own]], int)
        rms = [r for _, r in agreement[own]]
        print(f"| {name} | {len(views)} | {np.sum(views <= 5)} | {np.sum((views >= 6) & (views <= 7))} | "
              f"{np.sum(views >= 8)} | {np.median(rms) if rms else float('nan'):.2f} |")
    print("\n| fronts without a triangulated handle | how many | its pixels detected in 3+ views "
          "| seen (a view's sighting within 2 px) in 3+ views | in 1-2 | in none |"
          "\n|---|---|---|---|---|---|")
    for kind, counts in unsighted_views.items():
        detected, seen_in = np.array(counts, int).reshape(-1, 2).T
        few = np.sum((seen_in >= 1) & (seen_in <= 2))
        print(f"| {kind}s | {len(seen_in)} | {np.sum(detected >= 3)} | {np.sum(seen_in >= 3)} | {few} "
              f"| {np.sum(seen_in == 0)} |")
    print("\n| fronts without a triangulated handle, by grip | " + " | ".join(LOST_GRIPS) + " |\n|---|"
          + "---|" * len(LOST_GRIPS))
    print("| fronts | " + " | ".join(str(lost_grips.count(g)) for g in LOST_GRIPS) + " |")
    print_offset_types(typed, config)
    if args.csv_path is not None:
        write_rows_csv(args.csv_path, rows)


def print_offset_types(typed: list[tuple[str, SightedFront, bool]], config: FurnitureFitConfig) -> None:
    """The tables of where the handle sits across its read face and of the read types (docstring)."""
    edges = config.offset_edges
    lone = [(kind, handle_offset(front)) for kind, front, paired in typed if not paired]
    bins = {kind: np.bincount([int(np.searchsorted(edges, o, side="right")) for k, o in lone if k == kind],
                              minlength=len(edges) + 1) for kind in ("door", "drawer")}
    names = [f"{lo:g}-{hi:g}" for lo, hi in zip((0.0, *edges), (*edges, np.inf), strict=True)]
    print("\n| handle across its read face (lone fronts) | " + " | ".join(names) + " |\n|---|"
          + "---|" * len(names))
    for kind in ("door", "drawer"):
        print(f"| {kind}s ({bins[kind].sum()}) | " + " | ".join(map(str, bins[kind])) + " |")
    share = {kind: bins[kind] / max(bins[kind].sum(), 1) for kind in bins}
    with np.errstate(divide="ignore"):
        ratio = np.log(share["door"] / share["drawer"])
    print("| log-likelihood ratio, door against drawer | " + " | ".join(f"{r:+.2f}" for r in ratio) + " |")
    for name, odds in (("without the offset's odds", (0.0,) * len(names)),
                       ("with " + " / ".join(f"{o:+.2f}" for o in config.offset_type_log_odds),
                        config.offset_type_log_odds)):
        wrong = Counter()
        for kind, front, paired in typed:
            door = read_door_log_odds(front, paired, config.pair_type_log_odds, (edges, odds)) > 0.0
            wrong[kind] += int(door != (kind == "door"))
        print(f"read types wrong ({name}): doors {wrong['door']}, drawers {wrong['drawer']} of {len(typed)}")


if __name__ == "__main__":
    main()
