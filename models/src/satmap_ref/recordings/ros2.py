"""A scenario as a ROS 2 recording, written by `mcap-ros2-support` (CDR): per frame six
`sensor_msgs/msg/CompressedImage` (PNG), one `nav_msgs/msg/Odometry` (pose in `map`, twist in
`base_link`: REP 103, x forward, y left) and one `sensor_msgs/msg/Imu` (the acceleration)."""

import math
from pathlib import Path

from mcap_ros2.writer import Writer

from .scenario import NUM_CAMERAS, Scenario, anchor_toml, ego_to_ros_body

SEP = "=" * 80 + "\n"
HEADER = ("MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n" + SEP
          + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
QUATERNION = ("MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n"
              "float64 w 1\n")
# The message definitions as `ros2 bag record` stores them (the type, then each dependency).
COMPRESSED_IMAGE = "std_msgs/Header header\nstring format\nuint8[] data\n" + SEP + HEADER
ODOMETRY = (
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
    "geometry_msgs/TwistWithCovariance twist\n" + SEP + HEADER + SEP
    + "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n" + SEP
    + "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n" + SEP
    + "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n" + SEP + QUATERNION + SEP
    + "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n" + SEP
    + "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n" + SEP + VECTOR3)
IMU = (
    "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
    "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
    "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
    "float64[9] linear_acceleration_covariance\n" + SEP + HEADER + SEP + QUATERNION + SEP
    + VECTOR3)

ODOM_TOPIC = "/ego/odom"
IMU_TOPIC = "/imu"


def camera_topic(c: int) -> str:
    return f"/cam{c}/image/compressed"


def stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def vec(v) -> dict:
    return {"x": v[0], "y": v[1], "z": v[2]}


def write_ros2(scenario: Scenario, out: Path, skip: set[tuple[int, int]] = frozenset()) -> Path:
    """Write `out` and `out`'s topic mapping (`<stem>.topics.toml`); `skip` holds (frame,
    camera) pairs whose image is left out (a dropout)."""
    with open(out, "wb") as f:
        w = Writer(f)
        image = w.register_msgdef("sensor_msgs/msg/CompressedImage", COMPRESSED_IMAGE)
        odom = w.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY)
        imu = w.register_msgdef("sensor_msgs/msg/Imu", IMU)
        for k, fr in enumerate(scenario.frames):
            t = fr.stamp_ns
            for c in range(NUM_CAMERAS):
                if (k, c) in skip:
                    continue
                w.write_message(camera_topic(c), image, {
                    "header": {"stamp": stamp(t), "frame_id": f"cam{c}"},
                    "format": "png", "data": fr.images_png[c]}, log_time=t, publish_time=t)
            half = 0.5 * fr.yaw_rad
            w.write_message(ODOM_TOPIC, odom, {
                "header": {"stamp": stamp(t), "frame_id": "map"},
                "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": fr.x_m, "y": fr.y_m, "z": 0.0},
                                  "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half),
                                                  "w": math.cos(half)}},
                         "covariance": [0.0] * 36},
                "twist": {"twist": {"linear": vec(ego_to_ros_body(fr.velocity_mps)),
                                    "angular": vec(ego_to_ros_body(fr.rotation_rate_radps))},
                          "covariance": [0.0] * 36},
            }, log_time=t, publish_time=t)
            w.write_message(IMU_TOPIC, imu, {
                "header": {"stamp": stamp(t), "frame_id": "base_link"},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": [0.0] * 9,
                "angular_velocity": vec(ego_to_ros_body(fr.rotation_rate_radps)),
                "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": vec(ego_to_ros_body(fr.acceleration_mps2)),
                "linear_acceleration_covariance": [0.0] * 9,
            }, log_time=t, publish_time=t)
        w.finish()
    topics = out.with_suffix(".topics.toml")
    cameras = "".join(f'\n[[cameras]]\nindex = {c}\ntopic = "{camera_topic(c)}"\n'
                      f'frame_id = "cam{c}"\n' for c in range(NUM_CAMERAS))
    topics.write_text(
        anchor_toml(scenario.anchor)
        + f'\n[pose]\ntopic = "{ODOM_TOPIC}"\nparent_frame_id = "map"\n'
          'child_frame_id = "base_link"\n'
        + f'\n[motion]\ntopic = "{ODOM_TOPIC}"\nimu_topic = "{IMU_TOPIC}"\n' + cameras)
    return topics
