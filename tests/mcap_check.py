"""Reading a recording back with the other side: MCAP's own Python reader (``mcap``) and its protobuf
decoder (``mcap-protobuf-support``), which builds each message's class from the schema stored in the file,
so nothing of hrc's (nor of Foxglove's SDK, which wrote it) is used to read it.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

EXPECTED = {  # topic -> (schema name, schema encoding, message encoding)
    "/hrc/map": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
    "/hrc/routes": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
    "/hrc/agents": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
    "/hrc/human/pose": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
    "/hrc/robot/pose": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
    "/hrc/robot/goal": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
    "/hrc/in": ("hrc.Message", "jsonschema", "json"),
    "/hrc/out": ("hrc.Answer", "jsonschema", "json"),
    "/hrc/decision": ("hrc.Decision", "jsonschema", "json"),
    "/hrc/log": ("foxglove.Log", "protobuf", "protobuf"),
}


@dataclass
class Recorded:
    """What a file holds: header library, metadata, channels (topic -> schema name, schema encoding,
    message encoding), the summary's counts per topic, and every message in file order as
    (topic, log_time ns, publish_time ns, decoded: a protobuf message or the JSON value)."""

    library: str
    metadata: dict[str, dict[str, str]]
    channels: dict[str, tuple[str, str, str]]
    counts: dict[str, int]
    messages: list[tuple[str, int, int, Any]] = field(default_factory=list)

    def of(self, topic: str) -> list[Any]:
        return [m for t, _, _, m in self.messages if t == topic]

    def times(self, topic: str) -> list[float]:
        return [ns / 1e9 for t, ns, _, _ in self.messages if t == topic]


def read_mcap(source: Path | bytes, expected: dict[str, tuple[str, str, str]] | None = None) -> Recorded:
    """Read and decode every message; checks what any reader relies on: a summary whose statistics count
    what the data section holds, known channels with the expected schemas (`EXPECTED`, and `expected`: a
    team's channels per agent), log times never going back."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    data = source if isinstance(source, bytes) else Path(source).read_bytes()
    reader = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None, "no summary: the file was not closed"
    channels = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding,
                          c.message_encoding) for c in summary.channels.values()}
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    out = Recorded(reader.get_header().library, {m.name: dict(m.metadata) for m in reader.iter_metadata()},
                   channels, counts)
    decoder = DecoderFactory()
    last = -1
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        assert message.log_time >= last, f"{channel.topic}: time goes back at {message.log_time}"
        last = message.log_time
        if channel.message_encoding == "json":
            value = json.loads(message.data)
        else:
            decode = decoder.decoder_for(channel.message_encoding, schema)
            assert decode is not None, channel.topic
            value = decode(message.data)
        out.messages.append((channel.topic, message.log_time, message.publish_time, value))
    assert sum(counts.values()) == len(out.messages) == summary.statistics.message_count
    table = {**EXPECTED, **(expected or {})}
    for topic, kinds in channels.items():
        assert table.get(topic) == kinds, (topic, kinds)
    return out


EXPECTED_ROS2 = {  # topic -> (schema name, schema encoding, message encoding): --record-format ros2
    "/hrc/map": ("visualization_msgs/msg/MarkerArray", "ros2msg", "cdr"),
    "/hrc/routes": ("visualization_msgs/msg/MarkerArray", "ros2msg", "cdr"),
    "/hrc/agents": ("visualization_msgs/msg/MarkerArray", "ros2msg", "cdr"),
    "/hrc/human/pose": ("geometry_msgs/msg/PoseStamped", "ros2msg", "cdr"),
    "/hrc/robot/pose": ("geometry_msgs/msg/PoseStamped", "ros2msg", "cdr"),
    "/hrc/robot/goal": ("geometry_msgs/msg/PoseStamped", "ros2msg", "cdr"),
    "/hrc/in": ("std_msgs/msg/String", "ros2msg", "cdr"),
    "/hrc/out": ("std_msgs/msg/String", "ros2msg", "cdr"),
    "/hrc/decision": ("std_msgs/msg/String", "ros2msg", "cdr"),
}


def read_ros2_mcap(source: Path | bytes, expected: dict[str, tuple[str, str, str]] | None = None) -> Recorded:
    """`read_mcap` for a ROS-typed recording: decoded by ``mcap-ros2-support``'s decoder, which builds each
    type from the ``ros2msg`` definition stored in the file (MCAP's ``ros2`` profile); each message is
    kept as (topic, log time, publish time, (decoded, CDR bytes)) so that another decoder can read it too."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    data = source if isinstance(source, bytes) else Path(source).read_bytes()
    reader = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
    assert reader.get_header().profile == "ros2"
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None, "no summary: the file was not closed"
    channels = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding,
                          c.message_encoding) for c in summary.channels.values()}
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    out = Recorded(reader.get_header().library, {m.name: dict(m.metadata) for m in reader.iter_metadata()},
                   channels, counts)
    last = -1
    for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
        assert message.log_time >= last, f"{channel.topic}: time goes back at {message.log_time}"
        last = message.log_time
        out.messages.append((channel.topic, message.log_time, message.publish_time, (decoded, message.data)))
    assert sum(counts.values()) == len(out.messages) == summary.statistics.message_count
    table = {**EXPECTED_ROS2, **(expected or {})}
    for topic, kinds in channels.items():
        assert table.get(topic) == kinds, (topic, kinds)
    return out
