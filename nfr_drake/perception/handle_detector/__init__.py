"""A 2D handle detector: a small fully convolutional network that finds the handle in a photo.

The neural field pins a handle (1-4 px wide in the photos) down only loosely; this detector looks
for it in each photo directly, and `nfr_drake.perception.handle_triangulation` turns its output in
posed views into one 3D point. Per pixel it predicts whether the pixel shows the handle and, for
handle pixels, the offset (du, dv) in pixels to the projection of the handle keypoint (the grip
centre): a bar's visible pixels (posts included) are not centred on the grip, and their votes
are. It is trained on the same Drake renders as the neural field (label class 3 = handle), on
images of several sizes so that it works at any resolution: the network has no pooling and no
fully connected layer, so it runs on images of any size, and it sees about 65 px around each
pixel (dilated convolutions). A furniture detector trained with `--fronts` also holds a front
network (`FrontNet`), run on the photo scaled to 64 rows, whose outputs say what front lies behind
each sighted handle (`nfr_drake.perception.front_reading`).

Files in a model folder's `handle_detector/`: `config.json` (`HandleDetectorConfig` and training
record) and `model.safetensors`. A training run's `checkpoint/` is a resumable safetensors + JSON
checkpoint (`nfr_drake.nfr.checkpoint.write_training_checkpoint`); nothing is ever unpickled.

Modules, one role each:
- `model`: the network, its configuration, saving and loading a detector folder.
- `data`: training crops of rendered datasets with their handle masks and offset targets.
- `training`: the loss, the training loop (resumable) and its held-out measures.
- `command`: `nfr-drake train-handle-detector`.
"""
