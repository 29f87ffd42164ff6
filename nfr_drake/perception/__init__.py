"""Perception from real photos: camera poses by structure from motion, metric alignment, point clouds.

Modules, one role each (the camera model, with its COLMAP and OpenCV conversions and undistortion,
is `nfr_drake.data.camera.PinholeCamera`):
- `photos`: the photo folder: listing, reading, resizing to the working size.
- `sfm`: pycolmap structure from motion (SIFT, exhaustive matching, incremental mapping).
- `charuco`: ChArUco board detection and the board's pose in a photo.
- `alignment`: similarity transforms that take a reconstruction into metres, object poses.
- `report`: what a pose-estimation run did (registered images, errors, residuals, timings).
- `poses`: `nfr-drake poses`, photos -> capture set in frame O.
- `synthetic`: Drake-rendered photo folders of a closet in a textured room at known poses.
- `pointcloud`: semantically labelled point clouds (PLY).
- `handle_detector/`: the 2D handle detector (model, training data, training, its command).
- `handle_triangulation`: the detector's handle maps in posed views -> one 3D handle point.
"""
