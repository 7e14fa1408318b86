"""Fit your own pushes: simulate a dataset (stand-in for yours), validate, fit, read the summary.

    python examples/fit_your_data.py [OUTDIR]

With real data, write a dataset directory as in docs/data.md and start at the
validate step. Takes about half a minute.
"""

import json
import subprocess
import sys
from pathlib import Path

out = Path(sys.argv[1] if len(sys.argv) > 1 else "example-fit")
ds, run = out / "dataset", out / "run"
subprocess.run(["bayesrod", "simulate", "--preset", "grass", "--out", str(ds), "--seed", "7", "--force"], check=True)
subprocess.run(["bayesrod", "validate", str(ds)], check=True)
subprocess.run(["bayesrod", "fit", str(ds), "--out", str(run), "--prior", "grass", "--force", "--quiet"], check=True)
summary = json.loads((run / "summary.json").read_text())
for name in ("EI0", "p"):
    q = summary["parameters"][name]
    print(f"{name}: {q['median']:.4g}  90% interval [{q['q05']:.4g}, {q['q95']:.4g}]")
print("report:", (run / "report.html").resolve())
