"""A scenario as a Foxglove recording, written by the `mcap` package with the schemas of
`foxglove-schemas-protobuf` (descriptor sets by `mcap-protobuf-support`): per frame six
`foxglove.CompressedImage` (PNG), a `foxglove.FrameTransform` map -> base_link (x forward) and
the motion as `satmap.EgoMotion` JSON (no published schema carries an ego motion)."""

import json
import math
from pathlib import Path

from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set

from .scenario import NUM_CAMERAS, Scenario, anchor_toml

TF_TOPIC = "/tf"
MOTION_TOPIC = "/ego/motion"
EGO_MOTION_SCHEMA = {
    "title": "satmap.EgoMotion",
    "type": "object",
    "properties": {
        "timestamp": {"type": "object"},
        "acceleration_mps2": {"type": "array"},
        "rotation_rate_radps": {"type": "array"},
        "velocity_mps": {"type": "array"},
    },
}


def camera_topic(c: int) -> str:
    return f"/camera_{c}/compressed"


def write_foxglove(scenario: Scenario, out: Path) -> Path:
    """Write `out` and its topic mapping (`<stem>.topics.toml`)."""
    with open(out, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="satmap_ref.recordings")

        def schema(cls):
            return w.register_schema(name=cls.DESCRIPTOR.full_name, encoding="protobuf",
                                     data=build_file_descriptor_set(cls).SerializeToString())

        image, tf = schema(CompressedImage), schema(FrameTransform)
        motion = w.register_schema(name="satmap.EgoMotion", encoding="jsonschema",
                                   data=json.dumps(EGO_MOTION_SCHEMA).encode())
        cams = [w.register_channel(camera_topic(c), "protobuf", image) for c in range(NUM_CAMERAS)]
        tf_ch = w.register_channel(TF_TOPIC, "protobuf", tf)
        motion_ch = w.register_channel(MOTION_TOPIC, "json", motion)
        for fr in scenario.frames:
            t = fr.stamp_ns
            for c in range(NUM_CAMERAS):
                m = CompressedImage(frame_id=f"camera_{c}", format="png", data=fr.images_png[c])
                m.timestamp.FromNanoseconds(t)
                w.add_message(cams[c], log_time=t, data=m.SerializeToString(), publish_time=t)
            m = FrameTransform(parent_frame_id="map", child_frame_id="base_link")
            m.timestamp.FromNanoseconds(t)
            m.translation.x, m.translation.y = fr.x_m, fr.y_m
            m.rotation.z, m.rotation.w = math.sin(0.5 * fr.yaw_rad), math.cos(0.5 * fr.yaw_rad)
            w.add_message(tf_ch, log_time=t, data=m.SerializeToString(), publish_time=t)
            body = {"timestamp": {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000},
                    "acceleration_mps2": fr.acceleration_mps2,
                    "rotation_rate_radps": fr.rotation_rate_radps,
                    "velocity_mps": fr.velocity_mps}
            w.add_message(motion_ch, log_time=t, data=json.dumps(body).encode(), publish_time=t)
        w.finish()
    topics = out.with_suffix(".topics.toml")
    cameras = "".join(f'\n[[cameras]]\nindex = {c}\ntopic = "{camera_topic(c)}"\n'
                      for c in range(NUM_CAMERAS))
    topics.write_text(
        anchor_toml(scenario.anchor)
        + f'\n[pose]\ntopic = "{TF_TOPIC}"\nparent_frame_id = "map"\nchild_frame_id = "base_link"\n'
        + f'\n[motion]\ntopic = "{MOTION_TOPIC}"\n' + cameras)
    return topics
