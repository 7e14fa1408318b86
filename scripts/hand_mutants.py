"""Apply one-line changes to a file one at a time and run the tests that should catch each (docs/validation.md).

    python scripts/hand_mutants.py MUTANTS.json LOG

MUTANTS.json: ``{"file": path, "mutants": [{"old": text, "new": text, "tests": [pytest args]}, ...]}``; each
``old`` must occur exactly once in the file (else the line reads BADMATCH). Each change is applied, ``pytest -q -n0
-x`` runs on its ``tests``, the file is restored (also on interrupt), and one line is appended to LOG and printed:
killed, SURVIVED or NO TESTS RAN (pytest's exit code 5). Run it from the repository's root, on a clean tree: it
edits the checkout in place while it runs.
"""

import json
import subprocess
import sys
import time
from pathlib import Path


def main(argv=None) -> None:
    spec_path, log_path = (argv or sys.argv[1:])[:2]
    spec = json.loads(Path(spec_path).read_text())
    for m in spec["mutants"]:
        f = Path(m.get("file", spec["file"]))
        src = f.read_text()
        if src.count(m["old"]) != 1:
            line = f"BADMATCH {src.count(m['old'])} {m['old']!r}"
        else:
            try:
                f.write_text(src.replace(m["old"], m["new"]))
                t0 = time.time()
                cmd = [sys.executable, "-m", "pytest", "-q", "-n0", "-x", "-p", "no:cacheprovider", *m["tests"]]
                r = subprocess.run(cmd, capture_output=True, text=True)
                last = r.stdout.strip().splitlines()[-1] if r.stdout.strip() else ""
                verdict = {0: "SURVIVED", 5: "NO TESTS RAN"}.get(r.returncode, "killed")
                line = f"{verdict} [{time.time() - t0:.0f}s] {m['old']!r} -> {m['new']!r} | {last}"
            finally:
                f.write_text(src)
        with Path(log_path).open("a") as fh:
            fh.write(line + "\n")
        print(line, flush=True)


if __name__ == "__main__":
    main()
