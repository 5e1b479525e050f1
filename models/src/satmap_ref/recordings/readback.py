"""Every message of an MCAP file decoded by the public readers (`mcap` with the protobuf and
ROS 2 decoder factories; JSON channels with `json`), counted per topic."""

import json
from collections import Counter
from pathlib import Path

from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders


class JsonDecoders(DecoderFactory):
    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def decode_all(path: Path) -> tuple[Counter, dict[str, list]]:
    """(messages per topic, decoded messages per topic in file order)."""
    counts, decoded = Counter(), {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True,
                             decoder_factories=[ProtobufDecoders(), Ros2Decoders(), JsonDecoders()])
        for schema, channel, message, value in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            decoded.setdefault(channel.topic, []).append((schema.name, message.log_time, value))
    return counts, decoded
