"""`nfr-drake calibrate-confidence`: calibrate the fit confidence and check it out of distribution.

Runs the fits of `confidence_data.plan_cases` (resumable), computes each fit's features, fits a
logistic regression P(handle within 2 cm) on the calibration split alone (held-out objects of the
training world, capture seed 500, some with few views, occlusion or the object cut by the edge),
picks the threshold on that split (`pick_threshold`), and reports on the two splits it never saw:
the evaluation captures (how many good fits are refused) and the out-of-distribution ones (how many
fits more than 5 cm off are refused), and with `--rooms` on held-out rooms (`confidence_rooms`),
their confidence from the segmenter's masks and, to compare, from the border colour. Writes
OUT/features.csv, OUT/confidence.json, OUT/report.md and OUT/calibration.png, and with
`--write-models` the calibration into the model folders (`confidence.json`).

With `--scene room` it calibrates the fits in rooms instead, one calibration per model
(`room_calibration`): fitted on the pipeline's own room fits of a calibration seed
(`confidence_data.plan_room_cases`), checked on those of the pipeline's evaluation seed, written
as OUT/<closet|drawer>/confidence_room.json (with `--write-models` into models/closet and
models/drawer), beside OUT/report.md and OUT/calibration_<closet|drawer>.png.
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import sys
from pathlib import Path
from typing import Literal

import numpy as np

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.confidence_data import (
    EVALUATION_SEED,
    PIPELINE_ROOM,
    ROOM_VARIANTS,
    case_features,
    case_part_features,
    plan_cases,
    plan_furniture_cases,
    plan_room_cases,
    run_cases,
)
from nfr_drake.eval.confidence_rooms import room_captures
from nfr_drake.inference.confidence import (
    CONFIDENCE_FILE,
    FAR_M,
    ROOM_CONFIDENCE_FILE,
    SUCCESS_M,
    TRANSFORMS,
    ConfidenceModel,
    fit_logistic,
)
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import FittedModel
from nfr_drake.jsonio import write_rows_csv

TERMS = [("image_loss_worst_view", "log10"), ("silhouette_iou_worst_view", "one_minus"),
         ("edge_contact", "identity"), ("sighting_missing", "identity"),
         ("sighting_gap_m", "log10_cm"), ("code_distance", "identity"), ("views", "inverse")]
"""The logistic regression's terms (feature, transform; `inference.confidence.TRANSFORMS`), each
oriented so that more means a worse fit: its coefficient is held <= 0 (`calibrate`)."""

FURNITURE_TERMS = [("image_loss_worst_view", "log10"), ("silhouette_iou_worst_view", "one_minus"),
                   ("edge_contact", "identity"), ("sighting_missing", "identity"),
                   ("sighting_gap_m", "log10_cm"), ("code_distance", "identity"), ("views", "inverse"),
                   ("part_exists_logit", "negative"), ("start_spread_m", "log10_cm"),
                   ("part_image_loss", "log10"), ("part_unsighted", "identity"),
                   ("part_sighting_views", "negative"), ("part_sighting_rms_px", "identity")]
"""The terms of a model with several parts (furniture), per part: the fit's and the part's own
(`inference.confidence.part_features`; the sighting terms compare the slot's handle with the
handle detector's and weigh the evidence for the slot's own sighting, constant while the model
ships no detector)."""

ROOM_TERMS = TERMS + [("silhouette_iou", "one_minus"), ("image_loss", "log10"),
                      ("start_loss_ratio", "identity")]
"""The terms a room calibration starts from (`room_calibration`, which keeps as few as its split
supports): the object-alone terms and the mean view's silhouette IoU and image loss, and the
best start's loss over the second's (near 1: the starts explain the photos about equally well)."""

CLEAN_VARIANTS = ("clean", PIPELINE_ROOM)
"""The calibration fits whose successes the threshold must not refuse (`pick_threshold`): the
training world unchanged, and the room fits of the pipeline (the setting a room calibration is
for)."""

MAX_THRESHOLD = 0.5
"""The threshold is at most this: a fit more likely right than wrong is never refused."""

CV_FOLDS = 5
"""Folds of the cross-validation that chooses how many terms the data supports (`select_terms`)."""

MIN_EACH = 5
"""The calibration fits its terms only with at least this many successes and failures."""


def pick_threshold(p: np.ndarray, success: np.ndarray, clean: np.ndarray) -> float:
    """The refusal threshold from the calibration split: the highest t <= `MAX_THRESHOLD` that
    refuses none of its clean fits that succeed (p (N,) their probabilities, success and clean
    (N,) bool), i.e. just below the lowest such p, on a 0.01 grid."""
    floor = p[success & clean].min() if (success & clean).any() else MAX_THRESHOLD
    return float(min(MAX_THRESHOLD, np.floor(100 * floor - 1e-9) / 100))


BORDER_COLOUR = "rooms, border colour"
"""The split of the room fits' rows whose observed silhouette is the border colour's (as for an
object alone), to compare with the segmenter's ("rooms")."""


def featurize(lines: list[dict]) -> list[dict]:
    """Per fit line with a fit: its split, kind (variant, capture set of the evaluation and room
    splits, or the wrong model's category), handle error and features; a room fit gives a second
    row, split `BORDER_COLOUR`."""
    models: dict[str, FittedModel] = {}
    rows = []
    for line in lines:
        if line["handle_error_m"] is None:
            continue
        if line["variant"] == PIPELINE_ROOM:  # the features the pipeline's perception computed
            rows.append({"split": line["split"], "kind": f"rooms of seed {line['seed']}",
                         "model": line["model"], "capture": line["capture"],
                         "variant": line["variant"], "handle_error_m": line["handle_error_m"],
                         **line["features"]})
            continue
        if line["model"] not in models:
            models[line["model"]] = FittedModel(Path(line["model"]))
        fitted = models[line["model"]]
        if "part_errors" in line:  # a model of several parts: one row per true part
            kind = Path(line["capture"]).parent.name if line["split"] == "evaluation" else line["variant"]
            rows += [{"split": line["split"], "kind": kind, "model": line["model"],
                      "capture": line["capture"], "variant": line["variant"], **part}
                     for part in case_part_features(line, fitted)]
            continue
        wrong = line["category"] != line["model_category"]
        kind = (f"{line['model_category']} model on {line['category']}" if wrong
                else Path(line["capture"]).parent.name if line["split"] == "evaluation"
                else line["variant"])
        splits = [(line["split"], True)]
        if line["variant"] in ROOM_VARIANTS:
            pose = "estimated" if line["variant"] == "room_pose" else "given"
            kind = f"{Path(line['capture']).parent.name}, {pose} pose"
            splits.append((BORDER_COLOUR, False))
        for split, room in splits:
            features, _ = case_features(line, fitted, room)
            rows.append({"split": split, "kind": kind, "model": line["model"],
                         "capture": line["capture"], "variant": line["variant"],
                         "handle_error_m": line["handle_error_m"], **features})
    return rows


def monotone_terms(X: np.ndarray, y: np.ndarray, active: np.ndarray, l2: float) -> np.ndarray:
    """The terms kept of `active` (T,) bool once every term whose coefficient comes out > 0 is
    dropped, the most positive first, refitting after each (X (N, T) standardised, y (N,) 0/1)."""
    active = active.copy()
    while active.any():
        coef = fit_logistic(X[:, active], y, l2)[0]
        if coef.max() <= 0:
            break
        active[np.flatnonzero(active)[int(np.argmax(coef))]] = False
    return active


def log_loss(X: np.ndarray, y: np.ndarray, coef: np.ndarray, intercept: float) -> np.ndarray:
    """Per-row negative log-likelihood (N,) of 0/1 labels y under the logistic model."""
    p = np.clip(1.0 / (1.0 + np.exp(-(intercept + X @ coef))), 1e-12, 1 - 1e-12)
    return -(y * np.log(p) + (1 - y) * np.log(1 - p))


def cross_validated_loss(X: np.ndarray, y: np.ndarray, groups: np.ndarray, active: np.ndarray,
                         l2: float) -> tuple[float, float]:
    """Mean and standard error over the folds of the held-out log loss of the monotone model on
    the terms `active`, `CV_FOLDS` folds of whole groups (groups (N,) int: the capture of each
    row, so that the parts of one piece are never split between fitting and scoring)."""
    fold = groups % CV_FOLDS
    losses = []
    for k in range(CV_FOLDS):
        train, test = fold != k, fold == k
        if not test.any() or len(np.unique(y[train])) < 2:
            continue
        kept = monotone_terms(X[train], y[train], active, l2)
        coef = np.zeros(X.shape[1])
        coef[kept], intercept = fit_logistic(X[train][:, kept], y[train], l2)
        losses.append(log_loss(X[test], y[test], coef, intercept).mean())
    losses = np.array(losses)
    return float(losses.mean()), float(losses.std(ddof=1) / np.sqrt(len(losses)))


def select_terms(X: np.ndarray, y: np.ndarray, groups: np.ndarray, active: np.ndarray,
                 l2: float) -> np.ndarray:
    """As few terms as the data supports: backward elimination from the monotone terms `active`
    (each step drops the term whose loss costs the least in-sample likelihood), then the
    smallest set whose cross-validated log loss (`cross_validated_loss`, folds of whole
    captures) is within one standard error of the best set's. X (N, T) standardised, y (N,) 0/1,
    groups (N,) int; returns the chosen terms (T,) bool (possibly none: the success rate alone)."""
    path = [active.copy()]
    while path[-1].any():
        current, best = path[-1], None
        for t in np.flatnonzero(current):
            trial = current.copy()
            trial[t] = False
            trial = monotone_terms(X, y, trial, l2)
            coef = np.zeros(X.shape[1])
            coef[trial], intercept = fit_logistic(X[:, trial], y, l2)
            nll = log_loss(X, y, coef, intercept).sum()
            if best is None or nll < best[0]:
                best = (nll, trial)
        path.append(best[1])
    scores = [cross_validated_loss(X, y, groups, a, l2) for a in path]
    best = int(np.argmin([m for m, _ in scores]))
    limit = scores[best][0] + scores[best][1]
    return min((a for a, (m, _) in zip(path, scores, strict=True) if m <= limit),
               key=lambda a: a.sum())


def calibrate(rows: list[dict], terms: list[tuple[str, str]], source: dict, l2: float = 1.0,
              select: bool = False) -> ConfidenceModel:
    """The logistic regression on `rows` (features and handle_error_m) with the threshold of
    `pick_threshold`. Monotone: every term is oriented so that more is worse, and a term whose
    coefficient comes out > 0 (more of it, more confidence: the sample's quirk, e.g. occluded
    fits that are right in spite of a high image loss) is dropped (coefficient 0), the most
    positive first, until none is.

    With fewer than `MIN_EACH` successes (or failures) the terms cannot be fitted: the
    calibration is the split's success rate alone, (k + 1/2) / (n + 1) for k successes in n
    (Jeffreys), every coefficient 0, and the threshold `MAX_THRESHOLD` (while that rate is below
    it, every fit is refused).

    With `select` the terms are then cut to as few as the data supports (`select_terms`: fewer
    when there are few successes), each row's group for the cross-validation its `capture`; when
    none is left, the calibration is the success rate alone as above."""
    raw = ConfidenceModel(terms, [0.0] * len(terms), [1.0] * len(terms), [0.0] * len(terms), 0.0,
                          0.0, source)
    X = np.array([raw.design(r) for r in rows])
    mean, std = X.mean(0), X.std(0)
    std[std < 1e-9] = 1.0  # a term constant on the split (no detector, say): 0 here, no weight
    X = (X - mean) / std
    y = np.array([r["handle_error_m"] <= SUCCESS_M for r in rows], float)
    active = np.zeros(len(terms), bool)
    if min(y.sum(), len(y) - y.sum()) >= MIN_EACH:
        active = monotone_terms(X, y, ~active, l2)
    if select and active.any():
        groups = np.unique([r["capture"] for r in rows], return_inverse=True)[1]
        active = select_terms(X, y, groups, active, l2)
    if not active.any():
        rate = (y.sum() + 0.5) / (len(y) + 1.0)
        return ConfidenceModel(terms, mean.tolist(), std.tolist(), [0.0] * len(terms),
                               float(np.log(rate / (1.0 - rate))), MAX_THRESHOLD, source)
    coef = np.zeros(len(terms))
    coef[active], intercept = fit_logistic(X[:, active], y, l2)
    model = ConfidenceModel(terms, mean.tolist(), std.tolist(), coef.tolist(), intercept, 0.0, source)
    p = np.array([model.probability(r) for r in rows])
    model.threshold = pick_threshold(p, y > 0, np.array([r["variant"] in CLEAN_VARIANTS for r in rows]))
    return model


def rank_correlations(rows: list[dict], terms: list[tuple[str, str]]) -> list[float]:
    """Spearman's rank correlation of each term (feature, transform) with the handle error over
    `rows` (nan for a term constant on them): a term that is meant to grow with a worse fit
    should come out > 0."""
    from scipy.stats import spearmanr

    error = np.array([r["handle_error_m"] for r in rows])
    out = []
    for name, transform in terms:
        x = np.array([TRANSFORMS[transform](float(r[name])) for r in rows])
        out.append(float(spearmanr(x, error)[0]) if np.ptp(x) > 0 and np.ptp(error) > 0 else math.nan)
    return out


def refusal_table(rows: list[dict], model: ConfidenceModel) -> str:
    """Markdown: per split and kind of capture, fits, successes (handle within 2 cm) and how many
    of them are refused, fits far off (> 5 cm) and how many of them are refused."""
    lines = ["| split | captures | fits | within 2 cm | of which refused | more than 5 cm off | "
             "of which refused |", "|---|---|---|---|---|---|---|"]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["split"], r["kind"]), []).append(r)
        groups.setdefault((r["split"], "all"), []).append(r)
    for (split, kind), group in sorted(groups.items(), key=lambda g: (g[0][0], g[0][1] == "all", g[0][1])):
        error = np.array([r["handle_error_m"] for r in group])
        refused = np.array([model.probability(r) < model.threshold for r in group])
        good, far = error <= SUCCESS_M, error > FAR_M
        lines.append(f"| {split} | {kind} | {len(group)} | {good.sum()} | "
                     f"{(good & refused).sum()} | {far.sum()} | {(far & refused).sum()} |")
    return "\n".join(lines)


def plot_calibration(rows: list[dict], model: ConfidenceModel, path: Path, title: str = "") -> None:
    """Reliability diagram (predicted P against the observed share within 2 cm, per split),
    refusal curves (share of good in-distribution fits and of far-off fits refused against the
    threshold) and the handle errors (share of each split's fits within a distance); `title`
    above them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(15, 4.2))
    bins = np.linspace(0, 1, 6)
    for split, marker in (("calibration", "o"), ("evaluation", "s"), ("ood", "^")):
        group = [r for r in rows if r["split"] == split]
        if not group:
            continue
        p = np.array([model.probability(r) for r in group])
        y = np.array([r["handle_error_m"] <= SUCCESS_M for r in group])
        which = np.clip(np.digitize(p, bins) - 1, 0, len(bins) - 2)
        xs, ys, ns = [], [], []
        for b in range(len(bins) - 1):
            if (which == b).any():
                xs.append(p[which == b].mean())
                ys.append(y[which == b].mean())
                ns.append(int((which == b).sum()))
        ax.plot(xs, ys, marker=marker, label=f"{split} ({len(group)} fits)")
        for x, v, n in zip(xs, ys, ns, strict=True):
            ax.annotate(str(n), (x, v), textcoords="offset points", xytext=(4, -10), fontsize=7)
    ax.plot([0, 1], [0, 1], "k:", lw=1, label="perfect calibration")
    ax.set(xlabel="predicted P(handle within 2 cm)", ylabel="observed share within 2 cm",
           title="reliability (numbers: fits per bin)", xlim=(0, 1), ylim=(-0.02, 1.02))
    ax.legend(fontsize=8, loc="upper left")
    t = np.linspace(0, 1, 101)
    curves = (("evaluation", lambda e: e <= SUCCESS_M, "good fits refused, evaluation captures"),
              ("calibration", lambda e: e <= SUCCESS_M, "good fits refused, calibration captures"),
              ("ood", lambda e: e > FAR_M, "fits > 5 cm off refused, OOD captures"),
              ("evaluation", lambda e: e > FAR_M, "fits > 5 cm off refused, evaluation captures"))
    for split, chosen, label in curves:
        p = np.array([model.probability(r) for r in rows
                      if r["split"] == split and chosen(r["handle_error_m"])])
        if len(p):
            bx.plot(t, [(p < v).mean() for v in t], label=f"{label} ({len(p)})")
    bx.axvline(model.threshold, color="k", ls="--", lw=1, label=f"threshold {model.threshold:.2f}")
    bx.set(xlabel="threshold on P(handle within 2 cm)", ylabel="share refused",
           title="refusals against the threshold", xlim=(0, 1), ylim=(-0.02, 1.02))
    bx.legend(fontsize=8, loc="center right")
    for split in ("calibration", "evaluation", "ood"):
        error = np.sort([100.0 * r["handle_error_m"] for r in rows if r["split"] == split])
        if len(error):
            cx.step(error, np.arange(1, len(error) + 1) / len(error), where="post",
                    label=f"{split} ({len(error)} fits)")
    for cm, text in ((100 * SUCCESS_M, "2 cm"), (100 * FAR_M, "5 cm")):
        cx.axvline(cm, color="k", ls=":", lw=1)
        cx.annotate(text, (cm, 0.95), textcoords="offset points", xytext=(3, 0), fontsize=8)
    cx.set(xscale="log", xlabel="handle error (cm)", ylabel="share of fits within it",
           title="handle errors", ylim=(-0.02, 1.02))
    cx.legend(fontsize=8, loc="lower right")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def model_report(rows: list[dict], model: ConfidenceModel) -> str:
    """Markdown: the calibration's threshold and standardised coefficients, each term's rank
    correlation with the handle error over `rows` and their `refusal_table`."""
    terms = ", ".join(f"{t}({n}) {c:+.2f}" for (n, t), c in zip(model.terms, model.coef, strict=True))
    ranks = ", ".join(f"{t}({n}) {rho:+.2f}" for (n, t), rho in zip(
        model.terms, rank_correlations(rows, model.terms), strict=True))
    return (f"threshold {model.threshold:.2f}; standardised coefficients: {terms}; intercept "
            f"{model.intercept:+.2f}\n\nrank correlation of each term with the handle error "
            f"over all {len(rows)} rows (more of a term is meant to be worse: > 0): {ranks}\n\n"
            f"{refusal_table(rows, model)}\n")


def failures(failed: list[dict]) -> str:
    """Markdown: the cases without a fit (`failure` why), or "" when there are none."""
    if not failed:
        return ""
    return (f"\nno fit ({len(failed)}): "
            + "; ".join(f"{Path(f['capture']).parent.name}/{Path(f['capture']).name} "
                        f"{f['variant']}: {f['failure']}" for f in failed) + "\n")


def room_calibration(out: Path, calibration: range, evaluation: range, seed: int, fit: FitConfig,
                     write_models: bool, source: dict) -> str:
    """The room calibration per model (models/closet, models/drawer): the pipeline's room fits
    (`plan_room_cases`: the objects `calibration` of capture seed `seed`, `evaluation` of
    `EVALUATION_SEED`; kept in OUT/fits.jsonl), a logistic regression on each model's
    calibration fits from `ROOM_TERMS` cut to as few terms as they support (`calibrate`,
    `select_terms`; folds of whole objects), with its threshold (`pick_threshold`, every room
    fit counting as clean), written as OUT/<name>/confidence_room.json (with `write_models` into
    the model folder too) and plotted as OUT/calibration_<name>.png. Returns the report: per model
    its `model_report` and that of the object-alone calibration (the folder's confidence.json)
    on the same fits."""
    cases = plan_room_cases(calibration, evaluation, seed)
    keys = {c.key for c in cases}
    lines = [line for line in run_cases(cases, out / "fits.jsonl", fit) if line["key"] in keys]
    rows = featurize(lines)
    write_rows_csv(out / "features.csv", rows)
    report = ""
    for folder in ("models/closet", "models/drawer"):
        name, mine = Path(folder).name, [r for r in rows if r["model"] == folder]
        fitted_on = [r for r in mine if r["split"] == "calibration"]
        data = (f"room fits of the pipeline (eval-pipeline --perceive room --object-pose estimated, "
                f"perception only) with {folder}: objects {calibration.start}-{calibration.stop - 1} "
                f"of capture seed {seed}")
        model = calibrate(fitted_on, ROOM_TERMS, {**source, "data": data, "fits": len(fitted_on)},
                          select=True)
        (out / name).mkdir(exist_ok=True)
        model.write(out / name, ROOM_CONFIDENCE_FILE)
        if write_models:
            print(f"room calibration -> {model.write(Path(folder), ROOM_CONFIDENCE_FILE)}")
        report += f"## {name}: {ROOM_CONFIDENCE_FILE}\n\n{model_report(mine, model)}"
        alone = ConfidenceModel.read(Path(folder))
        if alone is not None:
            report += (f"\nThe object-alone calibration ({folder}/{CONFIDENCE_FILE}) on the same "
                       f"fits:\n\n{refusal_table(mine, alone)}\n")
        report += failures([line for line in lines
                            if line["model"] == folder and line["handle_error_m"] is None]) + "\n"
        plot_calibration(mine, model, out / f"calibration_{name}.png",
                         f"{name} in rooms: fitted on seed {seed}, checked on seed {EVALUATION_SEED}")
    return report


def calibrate_confidence_command(data: Path = Path("data/eval"),
                                 out: Path = Path("runs/confidence"), calibration: int = 40,
                                 evaluation: int = 30, closed: int = 20, shut128: int = 12,
                                 ood: int = 24,
                                 furniture: int = 12, rooms: int = 0,
                                 rooms_data: Path = Path("data/rooms"),
                                 write_models: bool = False, check: Path | None = None,
                                 fit: FitConfig = FitConfig(),
                                 category: Literal["closet-drawer", "furniture"] = "closet-drawer",
                                 calibration_captures: Path | None = None,
                                 scene: Literal["alone", "room"] = "alone", room_seed: int = 300,
                                 calibration_from: int = 0, evaluation_from: int = 0,
                                 threads: int | None = None) -> None:
    """Fit the confidence cases, calibrate P(handle within 2 cm) and report (module docstring).

    With `--category furniture` the furniture model (models/furniture, several parts) instead:
    `calibration` captures of DATA/furniture_calib (seed 500; `--calibration-captures` names
    another folder, e.g. the same pieces at 128 px), `evaluation` of
    DATA/furniture_cams128 (seed 7) and `ood` of DATA/furniture_oodsrc (seed 600, variants
    `FURNITURE_OOD_VARIANTS`), each fitted with the furniture fit's defaults; one row per true
    part with a handle (P(that part's handle within 2 cm), `FURNITURE_TERMS`); the other counts
    and `--rooms` are not used.

    Args:
        data: folder of the capture sets C_calib, C_train_cams, C_closed, C_shut128, C_oodsrc and
            furniture_oodsrc (docs/EVALUATION.md, "Fit confidence").
        out: output folder; OUT/fits.jsonl keeps the fits (a rerun fits only the missing ones).
        calibration: calibration captures per category (seed 500).
        evaluation: evaluation captures per category of C_train_cams (seed 0).
        closed: evaluation captures per category of C_closed (seed 3, shut).
        shut128: evaluation captures per category of C_shut128 (seed 200, shut, 128 px).
        ood: out-of-distribution captures per category (seed 600).
        furniture: furniture captures (seed 600), each fitted by the closet and the drawer model.
        rooms: rooms per held-out room set and category (ROOM_SETS of closets and drawers in
            `rooms_data`, written as capture sets to DATA/rooms), each fitted with the given pose
            and with the pose estimated from the segmenter's masks; never calibrated on.
        rooms_data: folder of the room datasets (`nfr-drake generate-rooms`, docs/ROOMS.md).
        write_models: also write the calibration to models/closet and models/drawer.
        check: a model folder whose confidence.json is checked instead (no calibration fits,
            nothing written to the models): e.g. the shipped calibration under another fit
            (`--fit.preset`).
        fit: options of the fit (closets and drawers).
        category: "closet-drawer" (models/closet and models/drawer, one calibration) or
            "furniture" (models/furniture).
        calibration_captures: with `--category furniture`, the folder of the calibration
            split's capture sets, furniture_000... (capture seed 500; default
            DATA/furniture_calib, 64 px): e.g. data/eval/furniture_calib128, the same pieces
            at 128 px as the handle detector's photos (`nfr-drake captures --size 128`).
        scene: "alone" (the object before a plain background, `confidence.json`) or "room": one
            calibration per model (`confidence_room.json`) on the pipeline's room fits
            (`room_calibration`): `calibration` objects per category of capture seed
            `room_seed` from index `calibration_from`, checked on `evaluation` objects of the
            pipeline's evaluation seed 200 from index `evaluation_from`; the other counts are
            not used.
        room_seed: with `--scene room`, the capture seed of the calibration's objects (not 200).
        calibration_from: with `--scene room`, the first calibration object's index.
        evaluation_from: with `--scene room`, the first evaluation object's index.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    checked = None if check is None else ConfidenceModel.read(check)
    if check is not None and checked is None:
        raise NfrDrakeError(f"--check {check}: no {CONFIDENCE_FILE} there")
    out.mkdir(parents=True, exist_ok=True)
    furniture_model = category == "furniture"
    if furniture_model and rooms:
        raise NfrDrakeError("--rooms: room fits are of closets and drawers, not --category furniture")
    if calibration_captures is not None and not furniture_model:
        raise NfrDrakeError("--calibration-captures: only with --category furniture (closets and "
                            "drawers calibrate on DATA/C_calib)")
    command = "nfr-drake " + " ".join(["calibrate-confidence", *sys.argv[2:]])
    source = {"command": command, "date": datetime.date.today().isoformat(),
              "machine": f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores"}
    if scene == "room":
        if furniture_model or check is not None or rooms:
            raise NfrDrakeError("--scene room: closets and drawers only, without --check and --rooms")
        report = room_calibration(out, range(calibration_from, calibration_from + calibration),
                                  range(evaluation_from, evaluation_from + evaluation), room_seed, fit,
                                  write_models, source)
        (out / "report.md").write_text(report)
        print(report + f"-> {out}/report.md, {out}/calibration_<model>.png, "
                       f"{out}/<model>/{ROOM_CONFIDENCE_FILE}")
        return
    room_sets = {} if rooms == 0 else {
        name: captures for c in ("closet", "drawer")
        for name, captures in room_captures(rooms_data, data / "rooms", c, rooms).items()}
    if furniture_model:
        cases = plan_furniture_cases(data, 0 if checked else calibration, evaluation, ood,
                                     calibration_captures)
    else:
        cases = plan_cases(data, 0 if checked else calibration, evaluation, closed, shut128, ood,
                           furniture, room_sets)
    keys = {c.key for c in cases}
    lines = [line for line in run_cases(cases, out / "fits.jsonl", fit) if line["key"] in keys]
    rows = featurize(lines)
    failed = [line for line in lines if line["handle_error_m"] is None]
    write_rows_csv(out / "features.csv", rows)
    calib_folder = calibration_captures or data / "furniture_calib"
    data_text = (f"calibration split: {calib_folder} (capture seed 500), "
                 f"{calibration} captures, variants by index: clean, clean, few_views, occluded, "
                 "edge_cut; one row per true part with a handle" if furniture_model else
                 "calibration split: closet_calib and drawer_calib (capture seed 500), "
                 f"{calibration} captures each, variants by index: clean, clean, few_views, "
                 "occluded, edge_cut; both categories pooled")
    source = {**source, "data": data_text,
              "fits": len([r for r in rows if r["split"] == "calibration"])}
    model = checked or calibrate([r for r in rows if r["split"] == "calibration"],
                                 FURNITURE_TERMS if furniture_model else TERMS, source,
                                 select=furniture_model)
    model.write(out)
    if write_models and checked is None:
        for folder in ("models/furniture",) if furniture_model else ("models/closet", "models/drawer"):
            print(f"calibration -> {model.write(Path(folder))}")
    report = model_report(rows, model) + failures(failed)
    (out / "report.md").write_text(report)
    plot_calibration(rows, model, out / "calibration.png")
    print(report + f"-> {out}/report.md, {out}/calibration.png, {out}/confidence.json")
