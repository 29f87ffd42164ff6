"""The planning evaluation's CSV: resuming, refusing a CSV of other columns, summaries by column."""

import csv

import pytest

from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.planning import FIELDS, PlanningEvalConfig, evaluate_planning, summarise


def test_a_csv_with_other_columns_is_refused(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text("category,seed,index,success\ncloset,7,0,True\n")
    with pytest.raises(NfrDrakeError, match="has the columns .* give another --csv"):
        evaluate_planning(PlanningEvalConfig(count=1, categories=("closet",)), path)


def test_done_rows_are_kept_and_summarised_by_part_type(tmp_path):
    path = tmp_path / "done.csv"
    rows = [dict.fromkeys(FIELDS, "") | dict(category="furniture", seed="7", index=str(i), part_type=t,
                                              planned="True", success=str(ok), planning_seconds="2.0",
                                              planning_cpu_seconds="1.0")
            for i, (t, ok) in enumerate([("door", True), ("drawer", True), ("drawer", False)])]
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    # Every object is in the CSV already: nothing is planned, the rows come back.
    done = evaluate_planning(PlanningEvalConfig(count=3, categories=("furniture",)), path)
    assert len(done) == 3
    summary = summarise(done, by="part_type")
    assert summary["drawer"]["count"] == 2 and summary["drawer"]["success"] == 0.5
    assert summary["all"]["success"] == pytest.approx(2 / 3)
