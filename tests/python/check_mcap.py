#!/usr/bin/env python3
"""Validate an MCAP file whose channels speak JSON with JSON Schema schemas.

Usage:
    check_mcap.py OUT.mcap [--expect-topics T [T ...]] [--expect-count T=N ...]
                           [--json]

Independent of tortwin's Rust code (it uses the `mcap` and `jsonschema`
Python packages), so it checks the twin's output the way Foxglove and other
tools will read it:

- the file is complete: it has a summary whose per-channel message counts
  match the messages actually stored, and every chunk's CRC is right;
- every channel has message_encoding "json" and a schema with encoding
  "jsonschema" that is itself a valid JSON Schema, in which every property
  (at every depth) has exactly one string `type`, but in Foxglove's own
  `foxglove.*` schemas, which the apps know by name (Foxglove Studio 1.48 and
  Lichtblick drop a topic whose schema has `"type": ["number", "null"]` or
  an untyped `enum`), and a map by `additionalProperties` also has
  `properties` (without, Studio 1.48 fails on the schema);
- every message is strict JSON (no NaN/Infinity) and validates against its
  channel's schema;
- every topic named by --expect-topics has at least one message, and every
  --expect-count TOPIC=N has exactly N.

Prints the message count per topic (or, with --json, one JSON object
{"topics": {topic: count}, "failures": [...]}) and exits 0 when all is well,
1 on any failure, 2 on a usage error and 3 when a Python package is missing
(install them with `pip install mcap jsonschema`).
"""

import argparse
import json
import sys

try:
    import jsonschema
    from mcap.reader import NonSeekingReader, SeekingReader
except ImportError as err:  # pragma: no cover - depends on the environment
    print(
        f"check_mcap.py: missing Python package ({err}); "
        "run `pip install mcap jsonschema`",
        file=sys.stderr,
    )
    sys.exit(3)

# How many failures to print per topic before only counting them.
MAX_REPORTED_PER_TOPIC = 5


def _reject_constant(name):
    raise ValueError(f"{name} is not valid JSON")


def _strict_json(data):
    """Parses bytes as strict JSON: Python's json accepts NaN and Infinity."""
    return json.loads(data.decode("utf-8"), parse_constant=_reject_constant)


def _parse_expect_count(text):
    topic, sep, count = text.rpartition("=")
    if not sep or not topic:
        raise argparse.ArgumentTypeError(f"expected TOPIC=N, got {text!r}")
    try:
        value = int(count)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected TOPIC=N, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"negative count in {text!r}")
    return topic, value


def untyped_properties(schema, path="#"):
    """Where a property of `schema` lacks a single string `type`.

    Foxglove Studio 1.48 (and Lichtblick) drop a topic whose schema has a
    property typed as a list (`["number", "null"]`) or not typed at all (an
    `enum` alone): every property, at every depth, needs exactly one string
    `type`.
    """
    found = []
    if not isinstance(schema, dict):
        return found
    for name, sub in (schema.get("properties") or {}).items():
        where = f"{path}/properties/{name}"
        if not isinstance(sub, dict) or not isinstance(sub.get("type"), str):
            kind = sub.get("type") if isinstance(sub, dict) else sub
            found.append(f"{where}: type {json.dumps(kind)}, not a single string")
        found.extend(untyped_properties(sub, where))
    # A map given by `additionalProperties` alone (wheel loads per rail):
    # Studio 1.48 fails on it with "Cannot convert undefined or null to
    # object" unless the schema also has `properties`.
    if isinstance(schema.get("additionalProperties"), dict) and "properties" not in schema:
        found.append(f"{path}: a map by additionalProperties without properties")
    for key in ("items", "additionalProperties"):
        if isinstance(schema.get(key), dict):
            found.extend(untyped_properties(schema[key], f"{path}/{key}"))
    for key in ("$defs", "definitions"):
        for name, sub in (schema.get(key) or {}).items():
            found.extend(untyped_properties(sub, f"{path}/{key}/{name}"))
    for key in ("oneOf", "anyOf", "allOf"):
        for k, sub in enumerate(schema.get(key) or []):
            found.extend(untyped_properties(sub, f"{path}/{key}/{k}"))
    return found


class Checker:
    def __init__(self):
        self.failures = []
        self._reported = {}
        # channel id -> (topic, validator or None when the channel is unusable)
        self._validators = {}
        self.counts = {}

    def fail(self, topic, message):
        self.failures.append(f"{topic}: {message}" if topic else message)

    def _fail_message(self, topic, message):
        """A per-message failure: printed for the first few of each topic."""
        n = self._reported.get(topic, 0) + 1
        self._reported[topic] = n
        if n <= MAX_REPORTED_PER_TOPIC:
            self.fail(topic, message)
        elif n == MAX_REPORTED_PER_TOPIC + 1:
            self.fail(topic, "more failing messages; not all listed")

    def _validator_for(self, schema, channel):
        if channel.id in self._validators:
            return self._validators[channel.id]
        topic = channel.topic
        self.counts.setdefault(topic, 0)
        validator = None
        if channel.message_encoding != "json":
            self.fail(topic, f"message_encoding is {channel.message_encoding!r}, not 'json'")
        elif schema is None:
            self.fail(topic, "channel has no schema")
        elif schema.encoding != "jsonschema":
            self.fail(topic, f"schema encoding is {schema.encoding!r}, not 'jsonschema'")
        else:
            try:
                document = _strict_json(schema.data)
                cls = jsonschema.validators.validator_for(document)
                cls.check_schema(document)
                validator = cls(document)
                # Foxglove's own schemas (foxglove.*) are known to the apps
                # by name; they type enums as oneOf consts.
                if not schema.name.startswith("foxglove."):
                    for problem in untyped_properties(document):
                        self.fail(topic, f"schema {schema.name!r}: {problem}")
            except (ValueError, jsonschema.exceptions.SchemaError) as err:
                self.fail(topic, f"schema {schema.name!r} is not a valid JSON Schema: {err}")
        self._validators[channel.id] = validator
        return validator

    def check_messages(self, stream):
        reader = NonSeekingReader(stream, validate_crcs=True)
        for index, (schema, channel, message) in enumerate(reader.iter_messages()):
            topic = channel.topic
            validator = self._validator_for(schema, channel)
            self.counts[topic] = self.counts.get(topic, 0) + 1
            where = f"message {index} (log_time {message.log_time})"
            try:
                document = _strict_json(message.data)
            except ValueError as err:
                self._fail_message(topic, f"{where}: not strict JSON: {err}")
                continue
            if validator is None:
                continue
            errors = sorted(validator.iter_errors(document), key=lambda e: [str(p) for p in e.path])
            for error in errors[:3]:
                path = "/".join(str(p) for p in error.path) or "(root)"
                self._fail_message(topic, f"{where}: at {path}: {error.message}")

    def check_summary(self, stream):
        summary = SeekingReader(stream).get_summary()
        if summary is None:
            self.fail(None, "no summary section: the file was not finished")
            return
        for channel in summary.channels.values():
            self.counts.setdefault(channel.topic, 0)
        if summary.statistics is None:
            self.fail(None, "summary has no statistics record")
            return
        stored = {}
        for channel_id, count in summary.statistics.channel_message_counts.items():
            channel = summary.channels.get(channel_id)
            topic = channel.topic if channel else f"<channel {channel_id}>"
            stored[topic] = stored.get(topic, 0) + count
        for topic in sorted(set(stored) | set(self.counts)):
            if stored.get(topic, 0) != self.counts.get(topic, 0):
                self.fail(
                    topic,
                    f"summary statistics count {stored.get(topic, 0)} messages, "
                    f"the file holds {self.counts.get(topic, 0)}",
                )


def main(argv=None):
    parser = argparse.ArgumentParser(
        description="Validate every message of an MCAP file against its channel's JSON Schema."
    )
    parser.add_argument("path", help="the MCAP file")
    parser.add_argument(
        "--expect-topics",
        nargs="+",
        default=[],
        metavar="TOPIC",
        help="topics that must hold at least one message",
    )
    parser.add_argument(
        "--expect-count",
        action="append",
        default=[],
        type=_parse_expect_count,
        metavar="TOPIC=N",
        help="a topic that must hold exactly N messages (repeatable)",
    )
    parser.add_argument("--json", action="store_true", help="print the result as one JSON object")
    args = parser.parse_args(argv)

    checker = Checker()
    try:
        with open(args.path, "rb") as stream:
            checker.check_messages(stream)
            stream.seek(0)
            checker.check_summary(stream)
    except OSError as err:
        checker.fail(None, f"cannot read {args.path}: {err}")
    except Exception as err:  # a malformed file: the mcap reader's own errors
        checker.fail(None, f"cannot parse {args.path} as MCAP: {type(err).__name__}: {err}")

    for topic in args.expect_topics:
        if checker.counts.get(topic, 0) == 0:
            checker.fail(topic, "expected at least one message, found none")
    for topic, expected in args.expect_count:
        found = checker.counts.get(topic, 0)
        if found != expected:
            checker.fail(topic, f"expected {expected} messages, found {found}")

    if args.json:
        print(json.dumps({"topics": checker.counts, "failures": checker.failures}, indent=2))
    else:
        for topic in sorted(checker.counts):
            print(f"{topic}\t{checker.counts[topic]}")
    for failure in checker.failures:
        print(f"FAIL {failure}", file=sys.stderr)
    if checker.failures:
        print(f"{args.path}: {len(checker.failures)} failure(s)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
