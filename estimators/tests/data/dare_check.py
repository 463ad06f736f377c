#!/usr/bin/env python3
"""Reference DARE solutions for estimators/tests/dare_scipy.rs.

Usage: python3 dare_check.py CASES.json

CASES.json is {"cases": [{"name": str, "a": [[..]], "b": [[..]], "q": [[..]], "r": [[..]]}, ...]}
(row-major nested lists). For each case this prints, as one JSON document on stdout,
{"scipy": version, "solutions": [{"name", "x", "closed_loop_radius"} or {"name", "error"}]}
where x = scipy.linalg.solve_discrete_are(a, b, q, r) (default balancing) and
closed_loop_radius = max |eig(A - B (R + B'XB)^-1 B'XA)| from numpy. Floats are printed with
repr, so they round-trip exactly.

Exits with status 3 and a message telling to `pip install scipy` when numpy or scipy is
missing: the Rust test must fail then, not skip.
"""

import json
import sys

try:
    import numpy as np
    import scipy
    import scipy.linalg
except ImportError as exc:  # pragma: no cover - the point is the message
    sys.stderr.write(
        f"dare_check.py: cannot import numpy/scipy ({exc}); "
        "install them with `python3 -m pip install scipy`\n"
    )
    sys.exit(3)


def solve(case):
    a = np.array(case["a"], dtype=float)
    b = np.array(case["b"], dtype=float)
    q = np.array(case["q"], dtype=float)
    r = np.array(case["r"], dtype=float)
    x = scipy.linalg.solve_discrete_are(a, b, q, r)
    gain = np.linalg.solve(r + b.T @ x @ b, b.T @ x @ a)
    rho = float(np.max(np.abs(np.linalg.eigvals(a - b @ gain))))
    return {"name": case["name"], "x": x.tolist(), "closed_loop_radius": rho}


def main():
    if len(sys.argv) != 2:
        sys.stderr.write("usage: dare_check.py CASES.json\n")
        sys.exit(2)
    with open(sys.argv[1], encoding="utf-8") as f:
        data = json.load(f)
    out = []
    for case in data["cases"]:
        try:
            out.append(solve(case))
        except Exception as exc:  # reported per case; the Rust test fails on it
            out.append({"name": case["name"], "error": f"{type(exc).__name__}: {exc}"})
    json.dump({"scipy": scipy.__version__, "solutions": out}, sys.stdout, allow_nan=False)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
