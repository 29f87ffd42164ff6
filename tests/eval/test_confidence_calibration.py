"""The fit-confidence calibration: monotone in every term, threshold from the calibration split."""

import numpy as np
import pytest

from nfr_drake.eval.confidence_calibration import calibrate, pick_threshold, refusal_table

TERMS = [("image_loss_worst_view", "log10"), ("silhouette_iou_worst_view", "one_minus")]


def _rows(n=300, seed=0):
    """Fits whose handle error grows with 1 - silhouette IoU, and whose image loss is *lower* on
    the bad fits (the wrong direction, as a sample's quirk may have it)."""
    rng = np.random.default_rng(seed)
    iou = rng.uniform(0.5, 1.0, n)
    error = np.where(rng.uniform(size=n) < (iou - 0.5) * 2, 0.01, 0.10)
    loss = np.where(error > 0.02, 10 ** rng.uniform(-3.5, -3, n), 10 ** rng.uniform(-3, -2, n))
    return [{"image_loss_worst_view": float(a), "silhouette_iou_worst_view": float(b),
             "handle_error_m": float(e), "variant": "clean", "split": "calibration", "kind": "clean",
             "views": 10.0}
            for a, b, e in zip(loss, iou, error, strict=True)]


def test_a_term_that_would_raise_confidence_with_a_worse_fit_is_dropped():
    rows = _rows()
    model = calibrate(rows, TERMS, {})
    assert model.coef[0] == 0.0 and model.coef[1] < 0.0  # image loss dropped; IoU kept
    p = [model.probability({"image_loss_worst_view": 1e-3, "silhouette_iou_worst_view": v})
         for v in np.linspace(0.5, 1.0, 11)]
    assert np.all(np.diff(p) > 0)  # a better silhouette, more confidence
    table = refusal_table(rows, model)
    assert "| calibration | clean | 300 |" in table


def test_the_threshold_refuses_no_clean_success_of_the_calibration_split():
    p = np.array([0.9, 0.37, 0.2, 0.8])
    success = np.array([True, True, False, True])
    assert pick_threshold(p, success, np.ones(4, bool)) == 0.36
    assert pick_threshold(p, success, np.array([True, False, True, True])) == 0.5  # at most 0.5


def test_without_enough_successes_the_calibration_is_the_success_rate_and_refuses_every_fit():
    rows = _rows()
    for r in rows:  # one success in 300 (as furniture fits of a weak model)
        r["handle_error_m"] = 0.3
    rows[0]["handle_error_m"] = 0.01
    model = calibrate(rows, TERMS, {})
    assert model.coef == [0.0, 0.0] and model.threshold == 0.5
    p = model.probability(rows[1])
    assert p == pytest.approx(1.5 / 301) and p == model.probability(rows[0])
    assert all(model.probability(r) < model.threshold for r in rows)
    assert model.weakest(rows[1]) is None  # no term to blame: the refusal gives the general advice


def test_rank_correlations_say_which_terms_grow_with_the_error():
    from nfr_drake.eval.confidence_calibration import rank_correlations

    rows = _rows()
    rho = rank_correlations(rows, TERMS + [("views", "inverse")])
    # 1 - IoU grows with the error; the image loss shrinks with it (the sample's quirk); a term
    # constant on the rows has no rank correlation.
    assert rho[1] > 0.3 and rho[0] < -0.3 and np.isnan(rho[2])


def _noisy_rows(n, successes_share, seed=0):
    """Rows of 3 parts per capture whose success depends on 1 - silhouette IoU alone; the image
    loss and the edge contact follow 1 - IoU loosely (more, worse, as terms are oriented) but
    say nothing more about success."""
    rng = np.random.default_rng(seed)
    iou = rng.uniform(0.0, 1.0, n)
    p = 1.0 / (1.0 + np.exp(-(np.log(successes_share / (1 - successes_share)) + 5.0 * (iou - 0.5))))
    error = np.where(rng.uniform(size=n) < p, 0.01, 0.10)
    loss = 10 ** (-2.5 + (1 - iou) + rng.normal(0, 0.7, n))
    edge = (1 - iou) + rng.normal(0, 0.7, n)
    return [{"image_loss_worst_view": float(a), "silhouette_iou_worst_view": float(b),
             "edge_contact": float(c), "handle_error_m": float(e), "variant": "clean",
             "split": "calibration", "kind": "clean", "capture": f"piece_{i // 3:03d}"}
            for i, (a, b, c, e) in enumerate(zip(loss, iou, edge, error, strict=True))]


NOISY_TERMS = TERMS + [("edge_contact", "identity")]


def test_term_selection_keeps_the_informative_term_and_drops_the_rest():
    rows = _noisy_rows(900, 0.3)
    chosen = calibrate(rows, NOISY_TERMS, {}, select=True)
    assert chosen.coef[1] < 0.0  # the silhouette IoU, which decides success, is kept
    assert chosen.coef[0] == 0.0 and chosen.coef[2] == 0.0  # its loose followers add nothing
    p = [chosen.probability({**rows[0], "silhouette_iou_worst_view": v}) for v in (0.2, 0.5, 0.9)]
    assert p[0] < p[1] < p[2]


def test_with_few_successes_term_selection_keeps_fewer_terms():
    rows = _noisy_rows(150, 0.3, seed=1)
    successes = [r for r in rows if r["handle_error_m"] <= 0.02]
    for r in successes[6:]:  # 6 successes: too few to tell most terms from noise
        r["handle_error_m"] = 0.10
    full = calibrate(rows, NOISY_TERMS, {})
    chosen = calibrate(rows, NOISY_TERMS, {}, select=True)
    assert sum(c != 0 for c in chosen.coef) < sum(c != 0 for c in full.coef)
    if not any(chosen.coef):  # none left: the success rate alone, every fit refused
        assert chosen.threshold == 0.5
        assert chosen.probability(rows[0]) == pytest.approx(6.5 / 151)


def test_the_furniture_calibration_captures_are_an_option(tmp_path):
    from nfr_drake.errors import NfrDrakeError
    from nfr_drake.eval.confidence_calibration import calibrate_confidence_command
    from nfr_drake.eval.confidence_data import CALIBRATION_VARIANTS, plan_furniture_cases

    default = plan_furniture_cases(tmp_path, 2, 1, 0)
    assert default[0].capture == str(tmp_path / "furniture_calib" / "furniture_000")
    cases = plan_furniture_cases(tmp_path, 7, 1, 1, tmp_path / "furniture_calib128")
    calib = [c for c in cases if c.split == "calibration"]
    assert [c.capture for c in calib] == [str(tmp_path / "furniture_calib128" / f"furniture_{i:03d}")
                                          for i in range(7)]
    assert [c.variant for c in calib] == [CALIBRATION_VARIANTS[i % 5] for i in range(7)]
    assert [c.seed for c in calib] == list(range(500, 507))
    # the evaluation and OOD captures stay in DATA
    assert {str(tmp_path / "furniture_cams128" / "furniture_000"),
            str(tmp_path / "furniture_oodsrc" / "furniture_000")} <= {c.capture for c in cases}
    with pytest.raises(NfrDrakeError, match="calibration-captures"):
        calibrate_confidence_command(data=tmp_path, out=tmp_path / "out",
                                     calibration_captures=tmp_path / "furniture_calib128")


def test_room_cases_are_the_pipelines_objects_never_calibrated_on_its_evaluation_seed():
    from nfr_drake.errors import NfrDrakeError
    from nfr_drake.eval.confidence_data import PIPELINE_ROOM, plan_room_cases

    cases = plan_room_cases(range(3), range(2), 300)
    assert [(c.model, c.split) for c in cases[:4]] == [
        ("models/closet", "calibration"), ("models/closet", "evaluation"),
        ("models/drawer", "calibration"), ("models/drawer", "evaluation")]
    assert [c.capture for c in cases[:2]] == ["pipeline_rooms/closet_300_0", "pipeline_rooms/closet_200_0"]
    assert len(cases) == 10 and {c.variant for c in cases} == {PIPELINE_ROOM}
    assert len({c.key for c in cases}) == 10
    later = plan_room_cases(range(5, 7), range(2, 4), 301)  # the objects asked for, by index
    assert [c.capture for c in later if "closet" in c.model] == [
        "pipeline_rooms/closet_200_2", "pipeline_rooms/closet_200_3", "pipeline_rooms/closet_301_5",
        "pipeline_rooms/closet_301_6"]
    with pytest.raises(NfrDrakeError, match="evaluation seed"):
        plan_room_cases(range(3), range(2), 200)


def test_each_model_gets_its_own_room_calibration_from_its_calibration_fits(tmp_path, monkeypatch):
    """Closets whose success follows the worst view's silhouette IoU, drawers whose success
    follows the handle detector's gap: each model's file keeps its own term."""
    from nfr_drake.eval import confidence_calibration
    from nfr_drake.eval.confidence_calibration import ROOM_TERMS, room_calibration
    from nfr_drake.inference.confidence import ROOM_CONFIDENCE_FILE, ConfidenceModel
    from nfr_drake.inference.fit import FitConfig

    rng = np.random.default_rng(0)

    made = []

    def fits(cases, out, fit):
        lines = made
        for case in cases:
            iou, gap = rng.uniform(0.2, 1.0), 10 ** rng.uniform(-3, -0.5)
            decisive = 1 - iou if "closet" in case.model else np.log10(gap) + 1.8
            success = rng.uniform() < 1 / (1 + np.exp(6 * decisive - 1))
            features = {"image_loss": 0.02, "image_loss_worst_view": 10 ** rng.uniform(-2, -1),
                        "silhouette_iou": 0.9, "silhouette_iou_worst_view": iou, "edge_contact": 0.0,
                        "sighting_missing": 0.0, "sighting_gap_m": gap, "start_loss_ratio": 0.5,
                        "code_distance": rng.uniform(0.5, 2.0), "views": 10.0, "room": 1.0}
            lines.append({"key": case.key, "model": case.model, "capture": case.capture,
                          "variant": case.variant, "split": case.split, "seed": case.seed,
                          "handle_error_m": 0.01 if success else 0.1, "features": features})
        return lines

    monkeypatch.setattr(confidence_calibration, "run_cases", fits)
    report = room_calibration(tmp_path, range(10, 310), range(20), 300, FitConfig(), False,
                              {"command": "test"})
    closet = ConfidenceModel.read(tmp_path / "closet", ROOM_CONFIDENCE_FILE)
    drawer = ConfidenceModel.read(tmp_path / "drawer", ROOM_CONFIDENCE_FILE)
    names = [n for n, _ in ROOM_TERMS]
    kept = {m: [n for n, c in zip(names, model.coef, strict=True) if c < 0]
            for m, model in (("closet", closet), ("drawer", drawer))}
    assert "silhouette_iou_worst_view" in kept["closet"] and "sighting_gap_m" not in kept["closet"]
    assert "sighting_gap_m" in kept["drawer"] and "silhouette_iou_worst_view" not in kept["drawer"]
    assert len(kept["closet"]) <= 3 and len(kept["drawer"]) <= 3  # the noise terms are cut
    assert closet.source["fits"] == drawer.source["fits"] == 300
    assert "objects 10-309 of capture seed 300" in closet.source["data"]
    for name, model in (("closet", closet), ("drawer", drawer)):
        # every room fit counts as clean: the threshold refuses none of the good calibration fits
        good = [r for r in confidence_calibration.featurize(made)
                if r["model"] == f"models/{name}" and r["split"] == "calibration"
                and r["handle_error_m"] <= 0.02]
        assert 0 < model.threshold <= 0.5 and len(good) > 20
        assert min(model.probability(r) for r in good) >= model.threshold
    assert "## closet: confidence_room.json" in report and "## drawer" in report
    assert (tmp_path / "calibration_drawer.png").is_file()
