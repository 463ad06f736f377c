#!/usr/bin/env python3
"""Check MCAP files with the official Python MCAP reader, independently of fdd's Rust code.

For each path given:

- open it with ``mcap.reader.make_reader(f, validate_crcs=True)`` and iterate every message
  (in log-time order, which also exercises the summary and chunk indexes; this checks chunk
  CRCs);
- read it once more from start to end with ``NonSeekingReader(f, validate_crcs=True)``, which
  also checks the data section CRC (covering the records the indexed read skips), and check
  that both reads see the same number of messages;
- check that the file has a summary, that every channel uses message encoding ``json`` and a
  ``jsonschema`` schema, and that log times do not go backwards;
- parse every message as strict JSON (UTF-8; ``NaN`` and ``Infinity`` are not JSON);
- if the ``jsonschema`` package is installed, validate every message against its channel's
  schema (``--require-jsonschema`` makes a missing package an error).

Prints one summary line per file (and up to ``--max-problems`` problem lines under a failing
one) and exits 0 when every file passed, 1 when any had a problem, 2 when the ``mcap`` package
is missing.

Usage: python3 tools/check_mcap.py [--require-jsonschema] FILE.mcap [FILE.mcap ...]
Needs: pip install mcap (and jsonschema for schema validation).
"""

import argparse
import json
import sys
from collections import Counter


def _reject_constant(name):
    raise ValueError(f"{name} is not valid JSON")


def check_file(path, make_reader, NonSeekingReader, jsonschema, max_problems):
    """Returns (summary line, list of problems)."""
    problems = []
    count = 0
    topics = Counter()
    first = last = None
    validators = {}  # schema id -> validator, or None when the schema itself is unusable
    channel_checked = set()

    def problem(text):
        problems.append(text)

    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            if summary is None:
                problem("no summary section (was the writer finished?)")
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                count += 1
                topic = channel.topic
                topics[topic] += 1
                t = message.log_time
                where = f"{topic} at {t} ns"
                if last is not None and t < last:
                    problem(f"{where}: log time goes backwards (previous {last} ns)")
                first = t if first is None else first
                last = t if last is None else max(last, t)

                if channel.id not in channel_checked:
                    channel_checked.add(channel.id)
                    if channel.message_encoding != "json":
                        problem(f"{topic}: message encoding {channel.message_encoding!r}, not 'json'")
                    if schema is None:
                        problem(f"{topic}: no schema")
                    elif schema.encoding != "jsonschema":
                        problem(f"{topic}: schema encoding {schema.encoding!r}, not 'jsonschema'")

                try:
                    obj = json.loads(message.data.decode("utf-8"), parse_constant=_reject_constant)
                except (UnicodeDecodeError, ValueError) as e:
                    problem(f"{where}: invalid JSON: {e}")
                    continue

                if jsonschema is None or schema is None or schema.encoding != "jsonschema":
                    continue
                if schema.id not in validators:
                    try:
                        schema_obj = json.loads(schema.data.decode("utf-8"))
                        cls = jsonschema.validators.validator_for(schema_obj)
                        cls.check_schema(schema_obj)
                        validators[schema.id] = cls(schema_obj)
                    except Exception as e:  # noqa: BLE001 - report any unusable schema
                        problem(f"{topic}: schema {schema.name!r} is not a valid JSON schema: {e}")
                        validators[schema.id] = None
                validator = validators[schema.id]
                if validator is None:
                    continue
                error = next(iter(validator.iter_errors(obj)), None)
                if error is not None:
                    at = "/".join(str(p) for p in error.absolute_path) or "(root)"
                    problem(f"{where}: does not match schema {schema.name!r} at {at}: {error.message}")
    except Exception as e:  # noqa: BLE001 - any reader failure is a problem with the file
        problem(f"unreadable: {type(e).__name__}: {e}")

    # The linear read checks the data section CRC too.
    if not problems:
        try:
            with open(path, "rb") as f:
                linear = sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages())
            if linear != count:
                problem(f"the linear read found {linear} messages, the indexed read {count}")
        except Exception as e:  # noqa: BLE001
            problem(f"linear read failed: {type(e).__name__}: {e}")

    schema_note = "schemas validated" if jsonschema is not None else "schemas NOT validated (no jsonschema package)"
    span = f"log time {first}..{last} ns" if first is not None else "no messages"
    stats = f"{count} messages on {len(topics)} topics, {span}, CRCs checked, {schema_note}"
    if problems:
        line = f"{path}: FAILED: {len(problems)} problem(s); {stats}"
    else:
        line = f"{path}: OK: {stats}"
    return line, problems[:max_problems], len(problems)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("paths", nargs="+", metavar="FILE.mcap")
    parser.add_argument(
        "--require-jsonschema",
        action="store_true",
        help="fail when the jsonschema package is not installed",
    )
    parser.add_argument("--max-problems", type=int, default=10, help="problem lines shown per file")
    args = parser.parse_args(argv)

    try:
        from mcap.reader import NonSeekingReader, make_reader
    except ImportError:
        print("check_mcap: the 'mcap' Python package is missing (pip install mcap)", file=sys.stderr)
        return 2
    try:
        import jsonschema
    except ImportError:
        jsonschema = None
        if args.require_jsonschema:
            print("check_mcap: the 'jsonschema' package is missing (pip install jsonschema)", file=sys.stderr)
            return 2

    failed = 0
    for path in args.paths:
        line, shown, total = check_file(
            path, make_reader, NonSeekingReader, jsonschema, args.max_problems
        )
        print(line)
        for p in shown:
            print(f"  {p}")
        if total > len(shown):
            print(f"  ... and {total - len(shown)} more")
        failed += bool(total)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
