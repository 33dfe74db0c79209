"""The extrinsic in the forms a ROS user pastes: ``static_transform_publisher`` arguments (ROS 1 and ROS 2) and a
URDF fixed ``<joint>``. Pure formatting of numbers; writing files is ``io.py``'s and the CLI's.

Direction. ROS names a transform by its parent and child frames: the transform published for
``parent -> child`` is the pose of the child frame in the parent frame, i.e. it maps points of the child frame
into the parent frame, ``p_parent = T_parent_child p_child``. With the lidar frame as parent and the camera
frame as child that is ``T_lidar_cam``; with the camera as parent it is ``T_cam_lidar``. A URDF joint's
``<origin>`` is the same ``T_parent_child``; its ``rpy`` are fixed-axis roll (x), pitch (y), yaw (z),
``R = Rz(yaw) Ry(pitch) Rx(roll)``. Quaternions are ``(x, y, z, w)``, scalar last, ``w >= 0``. Metres, radians.
Every number is printed with ``repr`` (17 significant digits), so parsing a line back gives the matrix exactly
(to rounding).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import CalibrationError
from ..geometry.transforms import invert_T, is_rigid, quaternion_xyzw

SENSORS = ("lidar", "camera")
FRAME_NAME = re.compile(r"[A-Za-z_/][A-Za-z0-9_/.\-]*")
"""A ROS frame / URDF link name as accepted here (no spaces, quotes or markup)."""
URDF_EULER = "xyz"
"""scipy's lower-case (extrinsic, fixed-axis) sequence x, y, z: URDF's roll-pitch-yaw."""


def _num(v: float) -> str:
    return repr(float(v))


def _nums(vs) -> str:
    return " ".join(_num(v) for v in vs)


@dataclass(frozen=True)
class FrameExport:
    """``T_parent_child`` (4x4, maps child-frame points into the parent frame) under ROS frame names."""

    parent: str
    child: str
    T_parent_child: np.ndarray
    source: str = "T_lidar_cam"
    """Which direction of the extrinsic ``T_parent_child`` is: ``T_lidar_cam`` or ``T_cam_lidar``."""

    @property
    def xyz(self) -> np.ndarray:
        """Translation (metres): the child frame's origin in the parent frame."""
        return self.T_parent_child[:3, 3].copy()

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        return quaternion_xyzw(self.T_parent_child[:3, :3])

    @property
    def rpy(self) -> np.ndarray:
        """URDF roll, pitch, yaw (radians, fixed axes x, y, z); see ``urdf_rpy``."""
        return urdf_rpy(self.T_parent_child[:3, :3])

    @property
    def tf_args(self) -> str:
        """``x y z qx qy qz qw parent child``: the positional arguments of ``static_transform_publisher``."""
        return f"{_nums(self.xyz)} {_nums(self.quaternion_xyzw)} {self.parent} {self.child}"

    @property
    def ros1(self) -> str:
        return f"rosrun tf2_ros static_transform_publisher {self.tf_args}"

    @property
    def ros2(self) -> str:
        """The ROS 2 form with named arguments (the positional ``tf_args`` are deprecated there)."""
        (x, y, z), (qx, qy, qz, qw) = self.xyz, self.quaternion_xyzw
        return ("ros2 run tf2_ros static_transform_publisher "
                f"--x {_num(x)} --y {_num(y)} --z {_num(z)} --qx {_num(qx)} --qy {_num(qy)} --qz {_num(qz)} "
                f"--qw {_num(qw)} --frame-id {self.parent} --child-frame-id {self.child}")

    def urdf_joint(self, name: str | None = None) -> str:
        """A fixed URDF ``<joint>`` from link ``parent`` to link ``child`` with this ``<origin>``."""
        name = name or f"{self.parent}_to_{self.child}"
        return (f'<joint name="{name}" type="fixed">\n'
                f'  <parent link="{self.parent}"/>\n'
                f'  <child link="{self.child}"/>\n'
                f'  <origin xyz="{_nums(self.xyz)}" rpy="{_nums(self.rpy)}"/>\n'
                "</joint>")


def urdf_rpy(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (radians) with ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (scipy's extrinsic ``"xyz"``).

    scipy's ``as_euler`` snaps the pitch to +-90 deg within about 1e-7 rad of gimbal lock, which moves the
    matrix by as much; here the pitch comes from ``atan2`` of the matrix entries (accurate to rounding), the yaw
    from its first column, and the roll from what remains, ``Rx(roll) = (Rz(yaw) Ry(pitch))^T R``, which
    absorbs the yaw's error near the lock, so the angles reproduce ``R`` to rounding everywhere.
    """
    R = np.asarray(R, float)
    pitch = np.arctan2(-R[2, 0], np.hypot(R[2, 1], R[2, 2]))
    yaw = np.arctan2(R[1, 0], R[0, 0])
    rest = Rotation.from_euler(URDF_EULER, [0.0, pitch, yaw]).as_matrix().T @ R
    return np.array([np.arctan2(rest[2, 1], rest[1, 1]), pitch, yaw])


def frame_export(T_lidar_cam: np.ndarray, parent: str, child: str, parent_sensor: str = "lidar") -> FrameExport:
    """The export of ``T_lidar_cam`` (maps camera points into the lidar frame) with frame ``parent`` naming the
    ``parent_sensor`` (``"lidar"``: publish ``T_lidar_cam``; ``"camera"``: publish ``T_cam_lidar``) and ``child``
    naming the other sensor. CalibrationError on a non-rigid matrix, an unknown sensor or bad frame names."""
    if parent_sensor not in SENSORS:
        raise CalibrationError(f"parent sensor must be one of {SENSORS}, got {parent_sensor!r}")
    for role, frame in (("parent", parent), ("child", child)):
        if not FRAME_NAME.fullmatch(frame or ""):
            raise CalibrationError(f"{role} frame name {frame!r} is not a frame name (letters, digits, _ / . -)")
    if parent == child:
        raise CalibrationError(f"parent and child frames are both {parent!r}")
    T = np.asarray(T_lidar_cam, float)
    if not is_rigid(T):
        raise CalibrationError("T_lidar_cam is not a rigid 4x4 transform")
    if parent_sensor == "lidar":
        return FrameExport(parent, child, T.copy(), "T_lidar_cam")
    return FrameExport(parent, child, invert_T(T), "T_cam_lidar")
