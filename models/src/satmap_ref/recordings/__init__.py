"""MCAP recordings of a scenario folder, written with the public MCAP writers (the `mcap`,
`mcap-ros2-support`, `mcap-protobuf-support` and `foxglove-schemas-protobuf` packages), and read
back with their readers: the independent side of `satmap-sim drive --mcap` / `--recording`.

- `scenario`: a scenario folder's frames (images, pose, motion) and files.
- `ros2`: a ROS 2 recording (`sensor_msgs/msg/CompressedImage`, `nav_msgs/msg/Odometry`,
  `sensor_msgs/msg/Imu`, CDR) and its topic mapping.
- `foxglove`: a Foxglove recording (`foxglove.CompressedImage`, `foxglove.FrameTransform`
  protobuf, `satmap.EgoMotion` JSON) and its topic mapping.
- `readback`: every message of an MCAP file decoded with the public readers, counted per topic.

`python -m satmap_ref.recordings --scenario DIR --flavour ros2|foxglove --out FILE.mcap` writes a
recording and its `topics.toml` beside it.
"""
