"""`nfr-drake captures --training-objects`: the dataset's own objects photographed anew."""

import json

from nfr_drake.data.captures import captures_command
from nfr_drake.data.generate import draw_object
from nfr_drake.data.shards import DatasetSpec


def test_training_objects_are_the_datasets_objects_under_new_draws(tmp_path):
    captures_command("furniture", n=2, out=tmp_path / "train", views=2, size=16, seed=0,
                     training_objects=True)
    captures_command("furniture", n=2, out=tmp_path / "unseen", views=2, size=16, seed=0)
    for i in range(2):
        trained = json.loads((tmp_path / "train" / f"furniture_{i:03d}" / "gt.json").read_text())
        unseen = json.loads((tmp_path / "unseen" / f"furniture_{i:03d}" / "gt.json").read_text())
        obj, _, _ = draw_object(DatasetSpec("furniture", 2, 1, 1, 16, 0), i)
        assert trained["object"]["name"] == obj.name
        assert trained["object"]["params"] == json.loads(json.dumps(obj.params))
        assert unseen["object"]["params"] != trained["object"]["params"]
