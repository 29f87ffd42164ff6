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
