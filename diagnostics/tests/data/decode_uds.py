#!/usr/bin/env python3
"""Independent decoder for tests/uds_services.rs: decodes fdd's UDS responses with the Python
`udsoncan` library and builds UDS requests with it, so the Rust side can compare.

Reads one JSON object on stdin:

    {"responses": [{"name": "...", "subfunction": 2, "payload": "5902ff012216...",
                    "ext_size": 1,            # optional, extended data bytes per record
                    "dids": [64768, 64769]}],  # optional, snapshot DIDs, decoded as '>f'
     "requests":  [{"name": "...", "service": "ReadDTCInformation", "subfunction": 4,
                    "dtc": 74262, "snapshot_record_number": 255}, ...]}

`subfunction` is absent for ClearDiagnosticInformation responses and for negative responses.
Prints one JSON object: {"responses": {name: decoded}, "requests": {name: payload hex}}.
Floats that are NaN are printed as null (JSON has no NaN); raw bytes are hex strings.

Exit status 3 with a message on stderr when udsoncan is not installed
(`python3 -m pip install udsoncan`); any decoding error is raised (non-zero exit).
"""
import json
import math
import sys

try:
    import udsoncan
    from udsoncan import Response
    from udsoncan.services import ClearDiagnosticInformation, ReadDTCInformation
except ImportError as e:  # pragma: no cover - reported to the Rust test
    print(f"udsoncan is not installed ({e}); run: python3 -m pip install udsoncan", file=sys.stderr)
    sys.exit(3)


def finite_or_none(v):
    # A pack-string codec ('>f') decodes to a 1-tuple.
    if isinstance(v, (tuple, list)) and len(v) == 1:
        v = v[0]
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def decode_dtc(dtc):
    out = {
        "id": dtc.id,
        "iso": dtc.id_iso(),
        "status": dtc.status.get_byte_as_int(),
        "snapshots": [],
        "snapshot_records": [],
        "extended_data": [],
    }
    for s in dtc.snapshots or []:
        if isinstance(s, int):  # reportDTCSnapshotIdentification: record numbers only
            out["snapshot_records"].append(s)
        else:
            out["snapshots"].append({
                "record": s.record_number,
                "did": s.did,
                "raw": bytes(s.raw_data).hex(),
                "value": finite_or_none(s.data),
            })
    for x in dtc.extended_data or []:
        out["extended_data"].append({"record": x.record_number, "raw": bytes(x.raw_data).hex()})
    return out


def decode_response(case):
    payload = bytes.fromhex(case["payload"])
    response = Response.from_payload(payload)
    if not response.valid:
        raise ValueError(f"{case['name']}: udsoncan says the response is invalid: {response.invalid_reason}")
    result = {"positive": response.positive, "service_id": response.service.request_id() if response.service else None}
    if not response.positive:
        result["nrc"] = response.code
        result["nrc_name"] = response.code_name
        return result
    if response.service is ClearDiagnosticInformation:
        ClearDiagnosticInformation.interpret_response(response)
        result["service"] = "ClearDiagnosticInformation"
        return result
    if response.service is not ReadDTCInformation:
        raise ValueError(f"{case['name']}: unexpected service {response.service}")
    didconfig = {did: ">f" for did in case.get("dids", [])}
    interpreted = ReadDTCInformation.interpret_response(
        response,
        case["subfunction"],
        extended_data_size=case.get("ext_size"),
        tolerate_zero_padding=False,
        ignore_all_zero_dtc=False,
        dtc_snapshot_did_size=2,
        didconfig=didconfig or None,
    )
    data = interpreted.service_data
    result["service"] = "ReadDTCInformation"
    result["subfunction_echo"] = data.subfunction_echo
    result["status_availability"] = (
        data.status_availability.get_byte_as_int() if data.status_availability is not None else None
    )
    result["dtc_format"] = data.dtc_format
    result["dtc_count"] = data.dtc_count
    result["dtcs"] = [decode_dtc(d) for d in data.dtcs]
    return result


def build_request(case):
    kwargs = {k: v for k, v in case.items() if k not in ("name", "service")}
    if case["service"] == "ReadDTCInformation":
        request = ReadDTCInformation.make_request(**kwargs)
    elif case["service"] == "ClearDiagnosticInformation":
        request = ClearDiagnosticInformation.make_request(**kwargs)
    else:
        raise ValueError(f"unknown service {case['service']}")
    return request.get_payload().hex()


def main():
    doc = json.load(sys.stdin)
    out = {
        "udsoncan_version": getattr(udsoncan, "__version__", "unknown"),
        "responses": {c["name"]: decode_response(c) for c in doc.get("responses", [])},
        "requests": {c["name"]: build_request(c) for c in doc.get("requests", [])},
    }
    json.dump(out, sys.stdout, indent=1, sort_keys=True, allow_nan=False)
    print()


if __name__ == "__main__":
    main()
