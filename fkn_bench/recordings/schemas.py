"""Message schemas fkn-bench writes: ROS 2 message definitions and Foxglove JSON schemas.

ROS message definitions are stored in MCAP ``Schema`` records the way ``rosbag2`` and
``mcap-ros2-support`` do (schema encoding ``ros2msg``): the definition of the top-level type,
followed by the definition of every type it depends on, each after a line of 80 ``=`` and a
``MSG: package/Type`` line. The field lists below are those of the standard ROS 2
``geometry_msgs``, ``std_msgs``, ``builtin_interfaces`` and ``nav_msgs`` packages. (The reader
needs no schema text: it decodes with ``rosbags``' typestores of the standard messages,
:mod:`~fkn_bench.recordings.codecs`.)

Foxglove schemas (``foxglove.PoseInFrame``) are JSON Schema documents (schema encoding
``jsonschema``, message encoding ``json``); Foxglove recognises them by name and draws the poses
in its 3-D panel.
"""

from __future__ import annotations

import json

__all__ = [
    "SEPARATOR", "ROS2_DEFINITIONS", "FOXGLOVE_POSE_IN_FRAME", "FOXGLOVE_SCHEMAS",
    "ros2_schema_text", "canonical_type_name"
]

SEPARATOR = "=" * 80

# Standalone ROS 2 definitions, keyed by the name used in "MSG:" lines (package/Type).
_ROS2_BASE: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/TwistStamped": "std_msgs/Header header\nTwist twist\n",
    "geometry_msgs/PoseWithCovariance": (
        "# Row-major 6x6 covariance of (x, y, z, rotation about X, rotation about Y, rotation about Z)\n"
        "Pose pose\nfloat64[36] covariance\n"
    ),
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/PoseWithCovarianceStamped": "std_msgs/Header header\nPoseWithCovariance pose\n",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
    ),
}


def _dependencies(name: str) -> list[str]:
    """The message types of the fields of ``name``, in field order (primitive types are lower case;
    a type without a package is in the package of ``name``)."""
    types = [line.split()[0] for line in _ROS2_BASE[name].splitlines() if not line.startswith("#")]
    package = name.split("/")[0]
    return [t if "/" in t else f"{package}/{t}" for t in types if "/" in t or t[0].isupper()]


def _concatenate(name: str) -> str:
    """The definition of ``name`` and, in first-use (depth-first) order, of its dependencies."""
    order: list[str] = []

    def visit(n: str) -> None:
        for dep in _dependencies(n):
            if dep not in order:
                order.append(dep)
                visit(dep)

    visit(name)
    return "".join([_ROS2_BASE[name], *(f"{SEPARATOR}\nMSG: {dep}\n{_ROS2_BASE[dep]}" for dep in order)])


def canonical_type_name(name: str) -> str:
    """``geometry_msgs/msg/PoseStamped`` and ``geometry_msgs/PoseStamped`` -> the latter."""
    return name.replace("/msg/", "/")


ROS2_DEFINITIONS: dict[str, str] = {
    n.replace("/", "/msg/"): _concatenate(n)
    for n in (
        "geometry_msgs/PoseStamped",
        "geometry_msgs/TwistStamped",
        "geometry_msgs/PoseWithCovarianceStamped",
        "nav_msgs/Odometry",
    )
}
"""ROS 2 schema name (``geometry_msgs/msg/PoseStamped``) -> concatenated ``ros2msg`` definition."""

def ros2_schema_text(name: str) -> str:
    """The ``ros2msg`` schema text of ``name`` (either spelling, see :func:`canonical_type_name`)."""
    return ROS2_DEFINITIONS[canonical_type_name(name).replace("/", "/msg/")]


def _number(description: str) -> dict:
    return {"type": "number", "description": description}


def _object(title: str, description: str, properties: dict, required: list[str]) -> dict:
    return {"title": title, "description": description, "type": "object", "properties": properties, "required": required}


_TIME = {
    "type": "object",
    "title": "time",
    "description": "Timestamp of the pose",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}

FOXGLOVE_POSE_IN_FRAME: dict = _object(
    "foxglove.PoseInFrame",
    "A timestamped pose in a named reference frame",
    {
        "timestamp": _TIME,
        "frame_id": {"type": "string", "description": "Frame of reference of the pose"},
        "pose": _object(
            "foxglove.Pose",
            "Position and orientation",
            {
                "position": _object(
                    "foxglove.Vector3", "Position, m", {k: _number(f"{k} coordinate") for k in "xyz"}, ["x", "y", "z"]
                ),
                "orientation": _object(
                    "foxglove.Quaternion",
                    "Orientation as a unit quaternion (x, y, z, w)",
                    {k: _number(f"{k} component") for k in "xyzw"},
                    ["x", "y", "z", "w"],
                ),
            },
            ["position", "orientation"],
        ),
    },
    ["timestamp", "frame_id", "pose"],
)
"""JSON Schema of ``foxglove.PoseInFrame`` (the fields Foxglove's 3-D panel uses)."""

FOXGLOVE_SCHEMAS: dict[str, bytes] = {
    "foxglove.PoseInFrame": json.dumps(FOXGLOVE_POSE_IN_FRAME, indent=2).encode(),
}
"""Foxglove schema name -> ``jsonschema`` schema data."""
