#!/usr/bin/python3
"""scripts/deviations --from-json: an earlier run's fits tabulated again against the bounds of
this build's scp-crb, the voltage's timing unknown where the fit estimated the interval.

  deviations_tables.py BUILD_DIR

Uses a stored run of bench/ (heavy-slow at N3, 30 seeds of the clean and held_after cells, whose
files leave the interval to the fit); exits 1 naming what is wrong."""

import json
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STORED = os.path.join(REPO, "bench", "deviations-heavy-slow-n3-30-interval-share-2026-12-07.json")


def main():
    build = sys.argv[1]
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "tables.md")
        proc = subprocess.run(["/usr/bin/python3", os.path.join(REPO, "scripts", "deviations"),
                               "--build", build, "--from-json", STORED, "--actuator", "heavy-slow",
                               "--noise", "N3", "--output", out], capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"scripts/deviations --from-json failed ({proc.returncode}): "
                     f"{proc.stderr.strip()[-600:]}")
        with open(os.path.splitext(out)[0] + ".json") as f:
            results = json.load(f)
        with open(STORED) as f:
            stored = json.load(f)
    cells = results["nuisance"]
    if sorted(cells) != ["clean", "held_after"]:
        failures.append(f"cells {sorted(cells)}, expected the stored run's clean and held_after")
    for name, cell in cells.items():
        runs = [j for j in stored["runs"] if j["cell"] == name]
        if cell["runs"] != len(runs):
            failures.append(f"{name}: {cell['runs']} runs tabulated of {len(runs)} stored")
        bound = cell.get("timing_bound") or {}
        if not bound.get("bounded"):
            failures.append(f"{name}: no bound with the voltage's delay unknown")
            continue
        for p in cell["parameters"][:4]:
            known, unknown = p.get("crb_rel"), p.get("crb_rel_timing_unknown")
            if not (known and unknown and unknown > known):
                failures.append(f"{name} {p['name']}: the delay-unknown bound {unknown} does not "
                                f"exceed the known-timing one {known}")
                continue
            ratio = p["refined"]["rms_rel"] / unknown
            if abs(p["refined_over_crb_timing_unknown"] - ratio) > 1e-12 * ratio:
                failures.append(f"{name} {p['name']}: ratio {p['refined_over_crb_timing_unknown']}"
                                f", rms / bound is {ratio}")
        if not bound.get("one_period_chi2", 0) > 0:
            failures.append(f"{name}: one_period_chi2 {bound.get('one_period_chi2')}")
    for line in failures:
        print("FAIL:", line)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
