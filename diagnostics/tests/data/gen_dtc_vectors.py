#!/usr/bin/env python3
"""Regenerates dtc_vectors.json: J2012 / UDS DTC encodings and status-byte flags decoded by two
independent Python libraries, for tests/dtc_codes.rs to check fdd's encoders against.

Optional: the tests read the committed JSON and never run this script. To regenerate:

    python3 -m venv /tmp/dtcvenv && /tmp/dtcvenv/bin/pip install obd udsoncan
    /tmp/dtcvenv/bin/python diagnostics/tests/data/gen_dtc_vectors.py > diagnostics/tests/data/dtc_vectors.json

Decoders used:
- obd.decoders.parse_dtc(bytes2) -> ("P0123", description) from the 2-byte code. It writes the
  last three characters in lowercase hex ("U3fff"), so compare case-insensitively. It returns
  None for the tuple (0, 0) (ELM327 padding) but decodes bytes 00 00 as "P0000"; the vectors
  pass bytes;
- udsoncan.Dtc(id3).id_iso() -> "P0123-1C" from the 3-byte UDS value;
- udsoncan.Dtc.Status.from_byte(b) -> the eight ISO 14229-1 flags of a status byte.
"""
import json
import random
import sys

import obd
import udsoncan
from obd.decoders import parse_dtc

LETTERS = "PCBU"


def code_vectors():
    values = set()
    # Every letter x every second digit x edge and typical low parts.
    for top in range(4):
        for digit in range(4):
            for low in (0x000, 0x001, 0x035, 0x100, 0x123, 0x234, 0x999, 0xABC, 0xFFF):
                values.add((top << 14) | (digit << 12) | low)
    # Named examples from REFERENCE.md section 5.
    values.update([0x0121, 0x0123, 0x4035, 0x4040, 0x4045, 0x4050, 0xC100, 0x9234, 0x2135,
                   0x0068, 0x0299, 0x3FFF, 0xFFFF, 0x0000])
    rng = random.Random(20261)
    values.update(rng.randrange(0x10000) for _ in range(200))
    out = []
    for v in sorted(values):
        hi, lo = v >> 8, v & 0xFF
        decoded = parse_dtc(bytes([hi, lo]))
        out.append({
            "u16": v,
            "bytes": [hi, lo],
            "obd": decoded[0] if decoded else None,
        })
    return out


def uds_vectors():
    values = set()
    for top in range(4):
        for digit in range(4):
            for low in (0x000, 0x123, 0xFFF):
                for ftb in (0x00, 0x1C, 0x71, 0xFF):
                    values.add((((top << 14) | (digit << 12) | low) << 8) | ftb)
    values.update([0x01231C, 0x403500, 0xC10000, 0x012316, 0x213562, 0x000000, 0xFFFFFF])
    rng = random.Random(20262)
    values.update(rng.randrange(0x1000000) for _ in range(200))
    return [{"u32": v, "udsoncan": udsoncan.Dtc(v).id_iso()} for v in sorted(values)]


def status_vectors():
    out = []
    for b in (0x00, 0x50, 0x27, 0x2F, 0xAF, 0x65, 0xEC, 0xAC, 0xA8, 0x28, 0x20, 0xFF):
        s = udsoncan.Dtc.Status.from_byte(b)
        out.append({
            "byte": b,
            "flags": {
                "testFailed": s.test_failed,
                "testFailedThisOperationCycle": s.test_failed_this_operation_cycle,
                "pendingDTC": s.pending,
                "confirmedDTC": s.confirmed,
                "testNotCompletedSinceLastClear": s.test_not_completed_since_last_clear,
                "testFailedSinceLastClear": s.test_failed_since_last_clear,
                "testNotCompletedThisOperationCycle": s.test_not_completed_this_operation_cycle,
                "warningIndicatorRequested": s.warning_indicator_requested,
            },
        })
    return out


def main():
    doc = {
        "generator": "diagnostics/tests/data/gen_dtc_vectors.py",
        "obd_version": obd.__version__,
        "udsoncan_version": udsoncan.__version__ if hasattr(udsoncan, "__version__") else None,
        "note": "obd: obd.decoders.parse_dtc(bytes) (lowercase hex digits: compare case-insensitively); "
                "udsoncan: udsoncan.Dtc(u32).id_iso(); status: udsoncan.Dtc.Status.from_byte",
        "codes": code_vectors(),
        "uds": uds_vectors(),
        "status": status_vectors(),
    }
    # One vector per line: readable diffs, small file.
    lines = ["{"]
    items = list(doc.items())
    for n, (key, value) in enumerate(items):
        end = "," if n + 1 < len(items) else ""
        if isinstance(value, list):
            lines.append(f" {json.dumps(key)}: [")
            for m, v in enumerate(value):
                lines.append("  " + json.dumps(v) + ("," if m + 1 < len(value) else ""))
            lines.append(" ]" + end)
        else:
            lines.append(f" {json.dumps(key)}: {json.dumps(value)}{end}")
    lines.append("}")
    sys.stdout.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
