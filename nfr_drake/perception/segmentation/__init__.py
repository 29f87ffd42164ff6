"""A 2D object segmenter: finds the target object in a photo of a room.

A tiny U-Net (`model.Segmenter`) trained on Drake renders of objects in random rooms
(`nfr_drake.data.rooms`, `nfr-drake generate-rooms`) labels each pixel as background, carcass,
moving part or handle of the target; `Segmenter.object_mask(image)` is the probability that a
pixel shows the object, (H, W), for a uint8 RGB image of any size, and
`Segmenter.carcass_amodal(image)` that it lies on the target's carcass as if nothing hid it
(trained on the amodal labels of `nfr_drake.data.amodal`). Files of a model folder
(`models/segmenter/`): `model.safetensors`, `config.json` (architecture and training record),
`MODEL_CARD.md`; nothing is ever unpickled. Results and failure cases: docs/ROOMS.md.

Modules, one role each:
- `model`: the network, its configuration, saving and loading a model folder.
- `data`: images of room datasets and augmented training batches.
- `training`: the loss and the resumable training loop.
- `crop`: the crop stage over posed views: a second, close look at the crop around the box of
  the object's pose from the first masks (`Segmenter.close_look` looks at one photo's crop).
- `refine`: the masks' edges by the photo's colours (GrabCut started from the probabilities).
- `evaluation`: mask IoU per dataset and the figure of predicted and true masks.
- `command`: `nfr-drake train-segmenter` and `nfr-drake eval-segmenter`.
"""
