"""Success rate of the whole pipeline (neural-field keypoints -> plan -> simulation), resumable.

`nfr-drake eval-pipeline` runs `run_scenario` on unseen objects `index = 0 .. n-1` of a capture
seed (or the chosen indices, `--objects`; each object is drawn from its index alone) and appends
one CSV row per object: perception errors, the fit's confidence, planning outcome, simulated
outcome. A fit refused for its low confidence (`Scenario.min_confidence`) is
not planned on: its row says `refused`, and the summary counts it apart from the failures. Rows
already in the CSV are kept, so a killed evaluation continues where it stopped. A piece of
furniture is opened at one part, drawn from the piece's own random stream (`Scenario.sample_piece`),
its row saying which (`PartRow`).
"""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm import tqdm

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import PAINTINGS
from nfr_drake.systems.articulation import SimulationConfig
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.place_task import PlaceTaskOutcome
from nfr_drake.systems.scenario import Scenario
from nfr_drake.systems.task import OPEN_TARGET, TaskOutcome


@dataclass
class PipelineRow:
    """One object's run; errors in cm (keypoints) and deg or cm (articulation, `unit`).

    handle_error_cm: predicted against true handle at the observed state. hinge_side_correct
    (doors; empty for drawers): whether the predicted hinge lies on the true hinge's side of the
    handle (the horizontal handle-to-hinge vectors point the same way; False for a door predicted
    as a drawer). p_handle_within_2cm: the
    fit's confidence (nan without a calibration); refused: the fit was not planned on (`failure`
    says why); planned, grasped and success are then False. grasped, final_error and
    max_drift_cm are the opening's (an open-and-place row's too, where the place then found no
    plan). pose_error_cm (xy) and
    pose_error_deg (yaw): the estimated object pose's errors (nan when the pose was given).
    grasp_tries: how many times the fingers closed on the handle (`SimulationConfig.regrasps`; 0
    when nothing was simulated). q_pulled: the articulation once the planned motion had settled,
    before a second pull, a door's turn or a guarded pull (nan when nothing was simulated).
    hinge_gap_cm: where a door's turn was measured, the hinge the hand felt against the
    keypoints' (`SimulationResult.hinge_gap`; nan otherwise). pulled_on: where the arm's reach
    ended a guarded pull and the robot pulled on from a second base (`systems.task.pull_on`), or a
    door's turn ended short and it turned on from one (`turn_on`), why ("panda_joint6 at its upper
    limit"); empty otherwise. success, final_error and max_drift_cm are
    then the second base's.
    """

    category: str
    index: int
    q_true: float
    q_estimate: float
    keypoint_rmse_cm: float
    handle_path_rmse_cm: float
    handle_error_cm: float
    hinge_side_correct: bool | None
    p_handle_within_2cm: float
    refused: bool
    planned: bool
    grasped: bool
    success: bool
    final_error: float
    unit: str
    max_drift_cm: float
    fit_seconds: float
    planning_seconds: float
    failure: str
    pose_error_cm: float
    pose_error_deg: float
    grasp_tries: int
    q_pulled: float
    hinge_gap_cm: float
    pulled_on: str


@dataclass
class PartRow(PipelineRow):
    """One piece of furniture's run: `PipelineRow`'s columns (of the part opened, `unit` deg for a
    door, cm for a drawer) and the part: its index in canonical order and its type."""

    part: int
    part_type: str


@dataclass
class PlaceRow(PipelineRow):
    """One object's open-and-place run: `PipelineRow`'s columns (those of the opening; success is
    the whole task's) and the place's: the grasp simulated, the item ("kind WxDxH cm"), whether
    the opening succeeded (as `task open` judges it; also where the place then found no plan),
    whether the item was picked, its distance to the true goal (cm), inside the compartment, and
    the front still open at the end."""

    grasp: str
    item: str
    opened: bool
    picked: bool
    item_error_cm: float
    inside: bool
    still_open: bool


def _row(scenario: Scenario) -> PipelineRow:
    outcome = run_scenario(scenario)
    revolute = outcome.truth.category == "closet"
    scale = np.degrees(1.0) if revolute else 100.0
    task = outcome.task
    sim = task.simulation if task is not None else None
    opening = task.opening if isinstance(task, PlaceTaskOutcome) else sim  # its SimulationResult
    pulled_on = task.pulled_on if task is not None else None
    ended = task.final if isinstance(task, TaskOutcome) else task.opened if task is not None else None
    if task is None:
        failure = outcome.refused
    elif task.plan is None:
        failure = task.planning_error
    else:
        failure = "" if task.success else task.summary() if isinstance(task, TaskOutcome) else sim.summary()
    handle = [kt.point("handle", kt.q_current) if kt else np.full(3, np.inf)
              for kt in (outcome.predicted, outcome.truth)]
    hinge_side = None
    if revolute and outcome.predicted is not None and outcome.predicted.category != "closet":
        hinge_side = False  # a furniture door the field takes for a drawer: no hinge at all
    elif revolute and outcome.predicted is not None:
        to_hinge = [(kt.point("hinge_bottom", kt.q_current) - h)[:2]
                    for kt, h in zip((outcome.predicted, outcome.truth), handle, strict=True)]
        hinge_side = bool(to_hinge[0] @ to_hinge[1] > 0.0)
    row = PipelineRow(
        category=scenario.category, index=scenario.index, q_true=outcome.q_true,
        q_estimate=outcome.q_estimate, keypoint_rmse_cm=outcome.keypoint_rmse_cm,
        handle_path_rmse_cm=outcome.handle_path_rmse_cm,
        handle_error_cm=float(100 * np.linalg.norm(handle[0] - handle[1])),
        hinge_side_correct=hinge_side,
        p_handle_within_2cm=_probability(outcome.confidence), refused=task is None,
        planned=task is not None and task.plan is not None,
        grasped=bool(opening and opening.grasped), success=task is not None and task.success,
        final_error=float(ended.joint_error * scale) if ended else float("nan"),
        unit="deg" if revolute else "cm",
        max_drift_cm=float(100 * ended.max_drift) if ended else float("nan"),
        fit_seconds=outcome.perception_seconds,
        planning_seconds=task.planning_seconds if task is not None else 0.0,
        failure=failure.replace("\n", " "),
        pose_error_cm=outcome.pose_error[0] if outcome.pose_error else float("nan"),
        pose_error_deg=outcome.pose_error[1] if outcome.pose_error else float("nan"),
        grasp_tries=opening.tries if opening else 0, q_pulled=opening.q_pulled if opening else float("nan"),
        hinge_gap_cm=100 * opening.hinge_gap if opening else float("nan"),
        pulled_on=pulled_on.reason if pulled_on is not None else "")
    if scenario.category == "furniture":
        return PartRow(**asdict(row), part=scenario.part, part_type="door" if revolute else "drawer")
    if scenario.task == "open":
        return row
    item = scenario.sample_item()
    opened = task is not None and task.opened is not None and task.opened.success
    return PlaceRow(**asdict(row), grasp=scenario.grasp, item=str(item), opened=opened,
                    picked=bool(sim and sim.picked),
                    item_error_cm=float(100 * sim.item_error) if sim else float("nan"),
                    inside=bool(sim and sim.inside), still_open=bool(sim and sim.still_open))


def _probability(confidence: dict | None) -> float:
    """P(handle within 2 cm) of a fit's confidence, nan when there is none."""
    p = (confidence or {}).get("p_handle_within_2cm")
    return float("nan") if p is None else float(p)


def object_scenario(base: Scenario, index: int, part_target: bool = False) -> Scenario:
    """`base` at object `index` with its part drawn (`Scenario.sample_piece`) and, with
    `part_target`, the q_target of the part's joint (`OPEN_TARGET`: a door's as a closet's, a
    drawer's as a drawer's)."""
    scenario = replace(base, index=index)
    obj, part = scenario.sample_piece()
    kind = "closet" if obj.front(part).joint_type == "revolute" else "drawer"
    return replace(scenario, part=part, q_target=OPEN_TARGET[kind] if part_target else base.q_target)


def evaluate_pipeline(base: Scenario, n: int | list[int], csv_path: Path, part_target: bool = False
                      ) -> list[dict]:
    """Run `base` on objects index = 0 .. n-1, or on the indices listed in `n` (`object_scenario`;
    `part_target`: each at its part's target), and append a `PipelineRow` per object to
    `csv_path` (objects of the category already there are skipped); returns the CSV's rows of the
    category (string values, as `csv.DictReader` reads them). An open-and-place task writes
    `PlaceRow`s, furniture `PartRow`s."""
    done = set()
    row_type = PlaceRow if base.task != "open" else PartRow if base.category == "furniture" else PipelineRow
    fields = list(row_type.__dataclass_fields__)
    if csv_path.exists():
        with open(csv_path) as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is not None and reader.fieldnames != fields:
                raise NfrDrakeError(f"{csv_path}: written with other columns (an older version); "
                                    "give another --csv-path")
            done = {(r["category"], int(r["index"])) for r in reader}
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    new_file = not csv_path.exists()
    with open(csv_path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        if new_file:
            writer.writeheader()
        indices = range(n) if isinstance(n, int) else n
        for i in tqdm(indices, desc=f"{base.category} pipeline", unit="object"):
            if (base.category, i) in done:
                continue
            writer.writerow(asdict(_row(object_scenario(base, i, part_target))))
            f.flush()
    with open(csv_path) as f:
        return [r for r in csv.DictReader(f) if r["category"] == base.category]


def eval_pipeline_command(category: Literal["closet", "drawer", "furniture"], model: Path, csv_path: Path,
                          n: int = 50, seed: int = 200, q_start: float = 0.0,
                          q_target: float | None = None,
                          keypoints: Literal["geometry", "head", "ground_truth"] = "head",
                          fit: FitConfig = FitConfig(), image_size: int = Scenario.image_size,
                          min_confidence: float = -1.0, task: Literal["open", "open-and-place"] = "open",
                          grasp: Literal["constraint", "contact"] = "constraint",
                          object_pose: Literal["given", "estimated"] = "given",
                          perceive: Literal["alone", "room"] = "alone",
                          segmenter: Path = Path(Scenario.segmenter),
                          room_loss: Literal["background", "masked"] = "background",
                          paintings: tuple[Literal["region", "fronts", "sure"], ...] = PAINTINGS,
                          mask_crop: bool = True,
                          aimed_look: Literal["off-aim", "always", "never"] = "off-aim",
                          look_again: bool = True,
                          refine_masks: bool = False,
                          objects: tuple[int, ...] = (),
                          guarded_pull: float = SimulationConfig.guarded_pull,
                          pull_on: bool = SimulationConfig.pull_on,
                          regrasps: int = SimulationConfig.regrasps,
                          turn_max_hinge_gap: float | None = SimulationConfig.second_turn_max_hinge_gap,
                          threads: int | None = None) -> None:
    """Open (or close) n unseen objects with neural-field keypoints, or open them and place an
    item inside; print the success rate. A piece of furniture is opened at one part drawn from its
    own random stream, the others held shut; its fit's confidence is P(that part's handle within
    2 cm) (models/furniture/confidence.json), and below the threshold the piece is refused.

    Args:
        category: object category.
        model: neural-field model folder of that category.
        csv_path: results CSV (appended; existing rows are kept and skipped).
        n: number of objects (indices 0 .. n-1 of the capture seed).
        objects: run these indices of the capture seed instead of 0 .. n-1 (each object and its
            item are drawn from the seed and its index alone, so a chosen one is the same as in a
            run of all; the summary covers the CSV's rows of the category).
        seed: capture seed of the objects.
        q_start: articulation when photographed.
        q_target: articulation to reach (default: 0.6 for closets and furniture doors, as in the
            ground-truth planning evaluation, 1.0 for drawers and furniture drawers).
        keypoints: keypoint source ("geometry" or "head"; "ground_truth": the object's own, no
            cameras and no fit, for comparison).
        fit: options of the fit (closets and drawers; furniture: `FurnitureFitConfig`'s defaults).
        image_size: square image size of the ten perception cameras, pixels.
        min_confidence: do not plan on a fit whose P(handle within 2 cm) is below this (below 0:
            the model's calibrated threshold, `confidence.json`; 0: never refuse); such objects
            are counted as refused, apart from the failures.
        task: "open", or "open-and-place" (then pick an item from a table beside the robot and
            place it at the goal keypoint; the CSV gets the place's columns, `PlaceRow`).
        grasp: how the hand holds the handle (and the item): "constraint" or "contact"
            (`Scenario.grasp`).
        object_pose: "given" (the true pose, the paper's setting) or "estimated" from the views
            (cameras around a coarse look; `Scenario.object_pose`); the CSV holds its errors.
        perceive: what the cameras see: the object "alone" (the paper's setting) or in a "room"
            (held-out textures and lights, the object's masks from `segmenter`; `Scenario.perceive`).
        segmenter: the segmenter's model folder (with `--perceive room`).
        room_loss: with `--perceive room`, the photos' pixels off the object's mask are painted in
            the training background ("background") or left out of the fit's loss ("masked").
        paintings: with `--room-loss background`, one fit per painting of the photos, the most
            confident kept (`Scenario.paintings`).
        mask_crop: with `--perceive room`, the segmenter's second, close look at the crop around
            the object's box estimated from its first masks, and at the crop around its carcass's
            box for the amodal carcass masks that give the pose (`Scenario.mask_crop`).
        aimed_look: with `--mask-crop` and `--object-pose estimated`, when the look at the crop
            around where the cameras aim gives the pose and masks: "off-aim" (where the whole
            photos' pose is not of the object aimed at, or none), "always" or "never"
            (`Scenario.aimed_look`).
        look_again: with `--mask-crop` and `--object-pose estimated`, a fit its confidence refuses
            is followed by one at the other look (aimed or whole photos), the more confident kept
            (`Scenario.look_again`).
        refine_masks: with `--room-loss background`, the masks' pixels that the photo's colours
            call background are taken off them before the painting (`Scenario.refine_masks`).
        guarded_pull: the constraint grasp's guarded pull to a drawer's stop goes on at most this
            far past the planned end, m (`SimulationConfig.guarded_pull`; 0: none, the pull ends
            at the plan's end).
        pull_on: where the arm's own reach ends that pull (a joint at its limit, links touching),
            the robot re-places its base and pulls on to the stop, and a door's turn that ended
            short is taken on from a second base too (`SimulationConfig.pull_on`); the CSV's
            pulled_on says why.
        regrasps: how many times the hand tries again after its fingers closed on nothing, 2 cm
            further along the approach, then 2 cm short of the planned grasp
            (`SimulationConfig.regrasps`; 0: one close).
        turn_max_hinge_gap: a door is turned by what the hand swept only when the hinge it felt
            lies within this of the keypoints' hinge, m (`SimulationConfig.second_turn_max_hinge_gap`;
            inf: always; default: by the grasp, 2 cm by contact, inf by constraint); the CSV's
            hinge_gap_cm holds the gap.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    base = Scenario(category=category, model=str(model), seed=seed, q_start=q_start,
                    q_target=1.0 if q_target is None else q_target, keypoints=keypoints, fit=fit,
                    image_size=image_size,
                    min_confidence=min_confidence, task=task, grasp=grasp, object_pose=object_pose,
                    perceive=perceive, segmenter=str(segmenter), room_loss=room_loss,
                    paintings=list(paintings), mask_crop=mask_crop, aimed_look=aimed_look,
                    look_again=look_again, refine_masks=refine_masks,
                    simulation=SimulationConfig(guarded_pull=guarded_pull, pull_on=pull_on, regrasps=regrasps,
                                                second_turn_max_hinge_gap=turn_max_hinge_gap))
    if any(i < 0 for i in objects):
        raise NfrDrakeError(f"--objects: indices must not be negative, got {list(objects)}")
    rows = evaluate_pipeline(base, list(objects) if objects else n, csv_path, part_target=q_target is None)
    print(SUMMARY_HEADER)
    print(summary_row(rows))
    print(perception_summary(rows))
    wins = sum(r["success"] == "True" for r in rows)
    refused = sum(r["refused"] == "True" for r in rows)
    if task != "open":
        print(place_summary(rows))
    if category == "furniture":
        print(part_summary(rows))
    pulled_on = [r for r in rows if r["pulled_on"]]
    if pulled_on:
        print(f"pulled on from a second base: {len(pulled_on)} "
              f"({sum(r['success'] == 'True' for r in pulled_on)} of them succeeded)")
    what = "" if task == "open" else f" {task} ({grasp} grasp)"
    print(f"{category}{what}: {wins}/{len(rows)} succeeded with {keypoints} keypoints "
          f"({100 * wins / max(len(rows), 1):.0f}%), {refused} refused for low fit confidence, "
          f"{len(rows) - wins - refused} failed")


SUMMARY_HEADER = ("| category | objects | refused | planned | grasped | success | failed | handle "
                  "error at the observed state, median (p10-p90) | hinge on the right side | "
                  "fit s (median) |\n|---|---|---|---|---|---|---|---|---|---|")


def summary_row(rows: list[dict]) -> str:
    """A markdown row (columns of `SUMMARY_HEADER`) summarising the CSV rows of one category;
    failed: neither refused nor a success."""
    count = lambda key: sum(r[key] == "True" for r in rows)  # noqa: E731
    handle = np.array([float(r["handle_error_cm"]) for r in rows])
    p10, p50, p90 = np.percentile(handle, [10, 50, 90])
    sides = [r["hinge_side_correct"] for r in rows if r["hinge_side_correct"] != ""]
    side = f"{sum(s == 'True' for s in sides)} / {len(sides)}" if sides else "n/a"
    fit = np.nanmedian([float(r["fit_seconds"]) for r in rows])
    failed = len(rows) - count("refused") - count("success")
    return (f"| {rows[0]['category']} | {len(rows)} | {count('refused')} | {count('planned')} | "
            f"{count('grasped')} | **{100 * count('success') / len(rows):.0f}%** | {failed} | "
            f"{p50:.1f} cm ({p10:.1f}-{p90:.1f}) | "
            f"{side} | {fit:.1f} |")


def perception_summary(rows: list[dict]) -> str:
    """One line on the perception of CSV rows: the keypoint RMSE at the observed state and, when
    the pose was estimated, its errors (medians) and how many lie within 2 cm and 2 degrees."""
    rmse = np.array([float(r["keypoint_rmse_cm"]) for r in rows])
    line = f"keypoint RMSE at the observed state: median {np.median(rmse):.2f} cm"
    if np.isinf(rmse).any():
        line += f" ({int(np.isinf(rmse).sum())} with no object pose, counted as inf)"
    pose = np.array([(float(r["pose_error_cm"]), float(r["pose_error_deg"])) for r in rows])
    if not np.isnan(pose).all():
        within = int(np.sum((pose[:, 0] <= 2.0) & (pose[:, 1] <= 2.0)))
        line += (f"; object pose: median {np.nanmedian(pose[:, 0]):.2f} cm, "
                 f"{np.nanmedian(pose[:, 1]):.2f} deg, {within}/{len(rows)} within 2 cm and 2 deg")
    return line


def part_summary(rows: list[dict]) -> str:
    """One line on furniture CSV rows (`PartRow`): successes and fits refused for low confidence
    (P(the part's handle within 2 cm)) per part type."""
    types = sorted({r["part_type"] for r in rows})
    count = lambda t, key: sum(r[key] == "True" for r in rows if r["part_type"] == t)  # noqa: E731
    wins = ", ".join(f"{t}s {count(t, 'success')}/{sum(r['part_type'] == t for r in rows)}" for t in types)
    refused = ", ".join(f"{t}s {count(t, 'refused')}" for t in types)
    return f"by part: {wins}; refused for low fit confidence: {refused}"


def place_summary(rows: list[dict]) -> str:
    """One line on the place of open-and-place CSV rows (`PlaceRow`): fronts opened (rows that have
    the column), items picked, inside the compartment, the median distance to the goal of those
    placed, fronts still open."""
    count = lambda key: sum(r.get(key) == "True" for r in rows)  # noqa: E731
    errors = [float(r["item_error_cm"]) for r in rows if r["inside"] == "True"]
    median = f"{np.median(errors):.1f} cm" if errors else "n/a"
    opened = f"{count('opened')} opened, " if rows and "opened" in rows[0] else ""
    return (f"place: {opened}{count('picked')}/{len(rows)} items picked, {count('inside')} inside (median "
            f"{median} from the goal), {count('still_open')} fronts still open")
