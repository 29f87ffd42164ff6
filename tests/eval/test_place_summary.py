"""The open-and-place evaluation's CSV columns and summary line."""

from nfr_drake.eval.pipeline_eval import PipelineRow, PlaceRow, place_summary


def test_place_rows_extend_the_pipeline_rows_and_are_summarised():
    assert list(PlaceRow.__dataclass_fields__)[:len(PipelineRow.__dataclass_fields__)] == list(
        PipelineRow.__dataclass_fields__)
    rows = [dict(picked="True", inside="True", item_error_cm="0.8", still_open="True"),
            dict(picked="True", inside="True", item_error_cm="1.6", still_open="False"),
            dict(picked="False", inside="False", item_error_cm="nan", still_open="True")]
    assert place_summary(rows) == ("place: 2/3 items picked, 2 inside (median 1.2 cm from the goal), "
                                   "2 fronts still open")
    opened = [dict(row, opened=state) for row, state in zip(rows, ("True", "True", "False"), strict=True)]
    assert place_summary(opened).startswith("place: 2 opened, 2/3 items picked")
