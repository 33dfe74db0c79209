"""Readers for the file formats calibration data already comes in, each feeding the project's data model.

- ``radlocc``: RADLOCC laser text (``timestamp start increment end unit N r1 r2 ...``) -> ``lidarcam.rig.dataset.Scan``;
  RADLOCC's ``PHI`` / ``DELTA`` result -> ``T_lidar_cam``.
- ``pcd``: PCD point clouds (ASCII or binary, fields x y [z] ...) of one 2D scan -> ``Scan``.
- ``bouguet``: a Bouguet toolbox ``Calib_Results.mat`` -> camera model and per-image board poses and corners.
- ``segmented``: hand-segmented board points per pose (CSV ``pose,x_m,y_m``) -> per-pose (K,2) arrays.
- ``camera_yaml``: camera intrinsics from ROS ``camera_info`` YAML, OpenCV FileStorage YAML or a Kalibr
  camchain -> ``lidarcam.rig.dataset.CameraModel``.

Every reader raises ``lidarcam.rig.dataset.DatasetError`` with one line naming the file, the line or field, and why.
"""
