#!/usr/bin/env python3
"""Check MPS run files (MCAP, format mps.v1) with the reference Python readers.

Usage: check_mcap.py [--partial] FILE.mcap [FILE.mcap ...]

For each file: opens it with ``mcap.reader.make_reader`` and the protobuf decoder of
``mcap-protobuf-support``, decodes EVERY message on every channel, and checks
- the channels /state, /particles, /diagnostics, /summary exist with their protobuf schemas
  (mps.v1.StateCheckpoint, foxglove.PointCloud, mps.v1.Diagnostics, mps.v1.Summary) and
  each has at least one message; per-channel sequence numbers count from 0, publish time =
  log time, message counts match the summary statistics;
- the metadata records manifest, build, run, outcome exist; SHA-256(manifest.canonical) =
  manifest.experiment_sha256; manifest.overrides is a JSON array of strings; the attachment
  manifest.yaml holds manifest.source;
- the single /summary message has a valid outcome that agrees with the outcome metadata, and
  the experiment hash of the manifest;
- every point cloud: stride > 0, data length = point_stride * number of points, fields inside
  the stride, x/y/z FLOAT32 and finite;
- every state checkpoint: array lengths consistent with its particle count and dimension.

--partial accepts files without summary section or footer (a killed run, a .partial file):
they are read record by record with the non-seeking reader up to the first unreadable record;
/summary and the outcome metadata are then not required.

Prints a per-channel table per file; exits 1 if any check fails, 2 on bad usage.
"""

import argparse
import hashlib
import json
import math
import struct
import sys
from collections import OrderedDict

from mcap.records import Attachment, Channel, Metadata, Message, Schema
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

CHANNELS = OrderedDict(
    [
        ("/state", "mps.v1.StateCheckpoint"),
        ("/particles", "foxglove.PointCloud"),
        ("/diagnostics", "mps.v1.Diagnostics"),
        ("/summary", "mps.v1.Summary"),
    ]
)
OUTCOMES = ("completed", "failed", "interrupted")
FLOAT32 = 7
# foxglove.PackedElementField.NumericType -> struct format
NUMERIC = {1: "B", 2: "b", 3: "H", 4: "h", 5: "I", 6: "i", 7: "f", 8: "d"}


class Run:
    """What one file holds, as the Python readers see it."""

    def __init__(self):
        self.complete = False
        self.tail_error = None
        self.schemas = {}  # id -> Schema
        self.channels = {}  # id -> Channel
        self.messages = []  # (Channel, Message, decoded)
        self.metadata = {}  # name -> dict
        self.attachments = []
        self.statistics = None


def read_complete(path):
    run = Run()
    run.complete = True
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            raise ValueError("no summary section (an unfinished run? try --partial)")
        run.schemas = dict(summary.schemas)
        run.channels = dict(summary.channels)
        run.statistics = summary.statistics
        for m in reader.iter_metadata():
            if m.name in run.metadata:
                raise ValueError(f"metadata record {m.name!r} appears twice")
            run.metadata[m.name] = dict(m.metadata)
        run.attachments = list(reader.iter_attachments())
        for _schema, channel, message, decoded in reader.iter_decoded_messages(
            log_time_order=False
        ):
            run.messages.append((channel, message, decoded))
    return run


def read_partial(path):
    """Record-by-record read that tolerates a missing footer and a cut-off tail."""
    run = Run()
    factory = DecoderFactory()
    decoders = {}
    with open(path, "rb") as f:
        records = StreamReader(f, validate_crcs=True).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                run.complete = True  # the stream reader found the footer and end magic
                break
            except Exception as e:  # noqa: BLE001 -- a truncated tail ends the read
                run.tail_error = f"{type(e).__name__}: {e}"
                break
            if isinstance(record, Schema):
                run.schemas[record.id] = record
            elif isinstance(record, Channel):
                run.channels[record.id] = record
            elif isinstance(record, Metadata):
                if record.name not in run.metadata:  # summary section may not repeat these
                    run.metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Attachment):
                run.attachments.append(record)
            elif isinstance(record, Message):
                channel = run.channels.get(record.channel_id)
                if channel is None:
                    raise ValueError(f"message on undeclared channel {record.channel_id}")
                if record.channel_id not in decoders:
                    schema = run.schemas.get(channel.schema_id)
                    decoders[record.channel_id] = factory.decoder_for(
                        channel.message_encoding, schema
                    )
                decoder = decoders[record.channel_id]
                if decoder is None:
                    raise ValueError(f"no protobuf decoder for channel {channel.topic}")
                run.messages.append((channel, record, decoder(record.data)))
    return run


def check_cloud(pc, where, fail):
    stride = pc.point_stride
    if stride == 0:
        fail(f"{where}: point_stride is 0")
        return
    n, rest = divmod(len(pc.data), stride)
    if rest != 0 or len(pc.data) != stride * n:
        fail(f"{where}: data length {len(pc.data)} is not point_stride {stride} * points")
        return
    if n == 0:
        fail(f"{where}: no points")
    fields = {}
    for fld in pc.fields:
        fmt = NUMERIC.get(fld.type)
        if fmt is None:
            fail(f"{where}: field {fld.name!r} has unknown numeric type {fld.type}")
            continue
        if fld.offset + struct.calcsize(fmt) > stride:
            fail(f"{where}: field {fld.name!r} at offset {fld.offset} overruns stride {stride}")
            continue
        fields[fld.name] = (fld.offset, fmt, fld.type)
    for axis in ("x", "y", "z"):
        if axis not in fields:
            fail(f"{where}: no {axis} field")
            return
        if fields[axis][2] != FLOAT32:
            fail(f"{where}: {axis} is not FLOAT32")
    for axis in ("x", "y", "z"):
        off, fmt, _ = fields[axis]
        unpack = struct.Struct("<" + fmt).unpack_from
        for i in range(n):
            v = unpack(pc.data, i * stride + off)[0]
            if not math.isfinite(v):
                fail(f"{where}: point {i} has {axis} = {v}")
                return
    if pc.frame_id == "":
        fail(f"{where}: empty frame_id")


def check_state(s, where, fail):
    d = s.dimension
    if d not in (2, 3):
        fail(f"{where}: dimension {d}")
        return
    n = len(s.kind)
    if len(s.position_m) != d * n or len(s.velocity_m_s) != d * n or len(s.pressure_pa) != n:
        fail(
            f"{where}: lengths position {len(s.position_m)}, velocity {len(s.velocity_m_s)}, "
            f"pressure {len(s.pressure_pa)} do not fit {n} particles in {d}D"
        )
    if any(not math.isfinite(v) for v in s.position_m):
        fail(f"{where}: non-finite position")


def check(path, partial):
    failures = []
    fail = failures.append
    try:
        run = read_partial(path) if partial else read_complete(path)
    except Exception as e:  # noqa: BLE001
        fail(f"cannot read: {type(e).__name__}: {e}")
        return failures, None
    if partial and run.tail_error:
        print(f"{path}: note: reading stopped at an unreadable tail ({run.tail_error})")

    # Channels and schemas.
    by_topic = {}
    for ch in run.channels.values():
        by_topic.setdefault(ch.topic, []).append(ch)
    for topic, schema_name in CHANNELS.items():
        chans = by_topic.get(topic, [])
        if len(chans) != 1:
            fail(f"{len(chans)} channels on {topic}, expected 1")
            continue
        ch = chans[0]
        schema = run.schemas.get(ch.schema_id)
        if ch.message_encoding != "protobuf":
            fail(f"{topic}: message encoding {ch.message_encoding!r}")
        if schema is None:
            fail(f"{topic}: no schema")
        elif schema.name != schema_name or schema.encoding != "protobuf":
            fail(f"{topic}: schema {schema.name!r} ({schema.encoding!r}), expected {schema_name}")

    # Messages (all decoded by now).
    counts = {}
    next_seq = {}
    summaries = []
    for channel, message, decoded in run.messages:
        topic = channel.topic
        i = counts.get(topic, 0)
        counts[topic] = i + 1
        where = f"{topic}[{i}]"
        expected_seq = next_seq.get(channel.id, 0)
        if message.sequence != expected_seq:
            fail(f"{where}: sequence {message.sequence}, expected {expected_seq}")
        next_seq[channel.id] = message.sequence + 1
        if message.publish_time != message.log_time:
            fail(f"{where}: publish time {message.publish_time} != log time {message.log_time}")
        if topic == "/particles":
            check_cloud(decoded, where, fail)
        elif topic == "/state":
            check_state(decoded, where, fail)
        elif topic == "/summary":
            summaries.append(decoded)
    for topic in CHANNELS:
        if counts.get(topic, 0) == 0 and not (partial and topic == "/summary"):
            fail(f"no message on {topic}")
    if run.statistics is not None:
        for ch_id, ch in run.channels.items():
            stat = run.statistics.channel_message_counts.get(ch_id, 0)
            seen = sum(1 for c, _, _ in run.messages if c.id == ch_id)
            if stat != seen:
                fail(f"{ch.topic}: statistics count {stat} messages, decoded {seen}")

    # Metadata.
    required = ["manifest", "build", "run"] + ([] if partial else ["outcome"])
    for name in required:
        if name not in run.metadata:
            fail(f"no metadata record {name!r}")
    manifest = run.metadata.get("manifest", {})
    for key in ("source", "canonical", "experiment_sha256", "overrides", "name"):
        if key not in manifest:
            fail(f"metadata manifest has no {key!r}")
    sha = manifest.get("experiment_sha256")
    if "canonical" in manifest and sha is not None:
        actual = hashlib.sha256(manifest["canonical"].encode("utf-8")).hexdigest()
        if actual != sha:
            fail(f"SHA-256 of manifest.canonical is {actual}, recorded {sha}")
    if "overrides" in manifest:
        try:
            ov = json.loads(manifest["overrides"])
            if not isinstance(ov, list) or not all(isinstance(s, str) for s in ov):
                fail("manifest.overrides is not a JSON array of strings")
        except json.JSONDecodeError as e:
            fail(f"manifest.overrides is not JSON: {e}")
    build = run.metadata.get("build", {})
    for key in ("crate_version", "git_commit", "rustc", "target", "profile"):
        if key not in build:
            fail(f"metadata build has no {key!r}")
    fmt = run.metadata.get("run", {}).get("mcap_format")
    if fmt != "mps.v1":
        fail(f"run.mcap_format is {fmt!r}, expected 'mps.v1'")
    manifests = [a for a in run.attachments if a.name == "manifest.yaml"]
    if len(manifests) != 1:
        fail(f"{len(manifests)} manifest.yaml attachments, expected 1")
    elif manifests[0].data.decode("utf-8") != manifest.get("source"):
        fail("attachment manifest.yaml differs from manifest.source")

    # Summary and outcome.
    if len(summaries) > 1:
        fail(f"{len(summaries)} /summary messages")
    outcome = run.metadata.get("outcome")
    if outcome is not None and outcome.get("status") not in OUTCOMES:
        fail(f"outcome metadata status {outcome.get('status')!r}")
    if summaries:
        s = summaries[0]
        if s.outcome not in OUTCOMES:
            fail(f"/summary outcome {s.outcome!r} is not one of {OUTCOMES}")
        if outcome is not None and (s.outcome, s.reason) != (
            outcome.get("status"),
            outcome.get("reason"),
        ):
            fail(f"/summary outcome {s.outcome!r}/{s.reason!r} differs from metadata {outcome}")
        if s.outcome == "completed" and s.reason:
            fail("/summary: completed with a reason")
        if sha is not None and s.experiment_sha256 != sha:
            fail(f"/summary experiment_sha256 {s.experiment_sha256!r} != manifest {sha!r}")
    return failures, (run, counts)


def print_table(path, run, counts):
    status = "complete" if run.complete else "no footer"
    print(f"{path} ({status})")
    print(f"  {'topic':<14} {'schema':<24} {'messages':>8}")
    topics = list(CHANNELS) + sorted({c.topic for c in run.channels.values()} - set(CHANNELS))
    for topic in topics:
        chans = [c for c in run.channels.values() if c.topic == topic]
        schema = run.schemas.get(chans[0].schema_id).name if chans and chans[0].schema_id in run.schemas else "-"
        print(f"  {topic:<14} {schema:<24} {counts.get(topic, 0):>8}")
    outcome = run.metadata.get("outcome", {})
    if outcome:
        print(f"  outcome: {outcome.get('status')} {outcome.get('reason', '')}".rstrip())


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("files", nargs="+", help="MCAP run files")
    parser.add_argument(
        "--partial",
        action="store_true",
        help="accept files without footer (killed runs); /summary and outcome not required",
    )
    args = parser.parse_args(argv)
    bad = 0
    for path in args.files:
        failures, result = check(path, args.partial)
        if result is not None:
            print_table(path, *result)
        else:
            print(path)
        for f in failures:
            print(f"  FAIL: {f}")
        if failures:
            bad += 1
    print(f"{len(args.files) - bad} of {len(args.files)} file(s) passed")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
