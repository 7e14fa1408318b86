"""Does a surviving mutant of the elastica solver change a number? A forward sweep, mutant against original.

``scripts/mutation.py`` lists the mutants that the selected unit tests let through, each with its diff. For
the solver's core (``--only elastica_core``) most survivors change the path of a search, a tie or a
tolerance, not its answer. This script settles which: it applies each survivor's diff to a copy of the
package, runs a forward sweep in a fresh process (both directions, contact from force with the shape grid
and force from displacement, over a plain rod, a taper, a base spring, a tilt, a rest curvature, self
weight, friction either way, a yield moment and a sensor offset, at several heights, and friction stems near
the tip and below a fold, where the base-moment search decides) and compares every number with the unmutated
code's: ``found``/``slipped``/``yielded`` must agree exactly and every value to
``--rtol`` (NaN where the original has NaN). A mutant that changes nothing here cannot change what the
likelihood reads from this solver on these rods; one that does is a missing test, unless the default suite's
other tests kill it: ``--tests`` runs them on each changed mutant (in a copy of the tracked tree).

Usage::

    python scripts/mutant_sweep.py RESULTS.json --target elastica_core --out classes.json
    python scripts/mutant_sweep.py RESULTS.json --out classes.json --tests tests/test_elastica.py tests/test_slip.py
    python scripts/mutant_sweep.py --compute OUT.npz        # the sweep alone, with the bayesrod on PYTHONPATH
    python scripts/mutant_sweep.py RESULTS.json --target moment_search --out classes.json --near-tip-only \
        --only-class same                # the survivors found the same, again on the dense friction stems only

The result (``--out``): per survivor ``same`` (every number within rtol), ``changed`` (with the largest
relative change and where), ``timeout``/``error`` (the mutant hangs or raises on the sweep: a user would see
that) or ``unapplied`` (its diff's lines were not found); with ``--tests``, a changed mutant that one of them
fails on is ``killed by the suite``; likewise one that raises or hangs.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutation import _copy_tree  # noqa: E402  (the same copy of the tracked tree mutmut's runs use)

MODULE = "bayesrod/physics/elastica.py"

#: (name, eta, p, nondimensional effects): each catalog effect the solver's core carries, alone or paired
CASES = [
    ("plain", 0.5, 0.0, {}),
    ("taper", 0.6, 0.5, {}),
    ("taper_high", 0.85, 0.3, {}),
    ("base_spring", 0.5, 0.3, {"c_base": 0.4}),
    ("tilt", 0.5, 0.3, {"tilt": 0.1}),
    ("rest_curvature", 0.5, 0.3, {"kappa0": 0.4}),
    ("weight", 0.5, 0.45, {"w0": 0.8}),
    ("friction", 0.45, 0.3, {"mu": 0.3}),
    ("friction_against", 0.5, 0.3, {"mu": -0.25}),
    ("friction_weight_spring", 0.4, 0.2, {"mu": 0.2, "w0": 0.5, "c_base": 0.2}),
    ("yield", 0.5, 0.3, {"m_yield": 1.0}),
    ("offset", 0.5, 0.3, {"f_offset": 0.05}),
]
FORCES = np.geomspace(0.05, 8.0, 14)
DISPLACEMENTS = np.linspace(0.0, 1.0, 11)
#: batches whose elements differ (a taper exponent and effects per element: the solver's per-element paths)
MIXED = [
    ("mixed_plain", np.array([0.5, 0.6, 0.75]), np.array([0.0, 0.3, 0.6]), {}),
    (
        "mixed_effects",
        np.array([0.5, 0.6, 0.75]),
        np.array([0.0, 0.3, 0.6]),
        {"c_base": np.array([0.0, 0.2, 0.4]), "mu": np.array([0.0, 0.15, -0.1]), "kappa0": np.array([0.2, 0.0, 0.1])},
    ),
]

#: friction stems whose contact nears the tip or a fold, where session 46's base-moment search decides (added in
#: session 49 for the ``moment_search`` target): (name, eta, p, effects, nondimensional forces f = F L^2 / EI0)
#: -- the islands and gaps near the tip (eta 0.5625, p 0.4, mu 0.424; its branch ends at 19.53), the holes below a
#: fold (eta 0.45, p 0.55, mu 0.2: 30 of the 100 forces without an equilibrium), the contact only the wide scan
#: finds (eta 0.45, p 0.3, mu 0.3 near f 26.74), a fold with holes at eta 0.6 (p 0.6, mu 0.2, its last held force
#: 4.011) and friction against the push (mu -0.25) to past its end. Dense: a force the search misses lies
#: between forces it holds, so a sparse sweep passes over a mutant that opens a hole (14 forces per case did).
NEAR_TIP = [
    ("friction_tip", 0.5625, 0.4, {"mu": 0.424}, np.linspace(13.0, 19.6, 200)),
    ("friction_fold", 0.45, 0.55, {"mu": 0.2}, np.linspace(12.5, 14.5, 100)),
    ("friction_wide_scan", 0.45, 0.3, {"mu": 0.3}, np.linspace(20.0, 28.0, 100)),
    ("friction_fold_high", 0.6, 0.6, {"mu": 0.2}, np.linspace(3.0, 4.1, 100)),
    ("friction_against_end", 0.5, 0.3, {"mu": -0.25}, np.linspace(2.0, 12.0, 100)),
]


def _readable(a: dict) -> dict:
    """What :func:`~bayesrod.physics.elastica.contact_from_force` lets a user read of a force-direction solve:
    without an equilibrium (not found, or past yield) no contact, moment or shape (NaN), only the flags."""
    hold = np.asarray(a["found"]) & ~np.asarray(a["yielded"])
    out = dict(a)
    for k in ("sig_c", "xi_c", "phi_c", "m0"):
        out[k] = np.where(hold, a[k], np.nan)
    if "grid" in a:
        out["grid"] = np.where(hold, a["grid"], np.nan)
    return out


def compute(near_tip_only: bool = False) -> dict[str, np.ndarray]:
    """The sweep with whatever bayesrod is importable: arrays keyed ``<case>/<direction>/<field>``
    (``near_tip_only``: only the friction stems of :data:`NEAR_TIP`)."""
    from bayesrod.physics.elastica import contact_from_force_nd, force_from_displacement_nd

    out = {}
    for name, eta, p, eff in [] if near_tip_only else CASES:
        a = _readable(contact_from_force_nd(FORCES * eta**-2, eta, p, eff, keep_shape=True))
        for k, v in a.items():
            out[f"{name}/force/{k}"] = np.asarray(v)
        b = force_from_displacement_nd(DISPLACEMENTS * eta, eta, p, eff)
        for k, v in b.items():
            out[f"{name}/displacement/{k}"] = np.asarray(v)
    for name, eta, p, eff in [] if near_tip_only else MIXED:
        a = _readable(contact_from_force_nd(FORCES[:, None] * eta**-2, eta, p, eff, keep_shape=True))
        b = force_from_displacement_nd(DISPLACEMENTS[:, None] * eta, eta, p, eff)
        out.update({f"{name}/force/{k}": np.asarray(v) for k, v in a.items()})
        out.update({f"{name}/displacement/{k}": np.asarray(v) for k, v in b.items()})
    for name, eta, p, eff, f in NEAR_TIP:
        a = _readable(contact_from_force_nd(f, eta, p, eff, keep_shape=True))
        out.update({f"{name}/force/{k}": np.asarray(v) for k, v in a.items()})
    return out


def compare(ref: dict, new: dict, rtol: float) -> tuple[bool, str]:
    """Same numbers? (flags exactly, values to rtol relative to the field's scale, NaN where NaN)."""
    worst, where = 0.0, ""
    for k, r in ref.items():
        if k not in new:
            return False, f"{k} missing"
        n = new[k]
        if r.shape != n.shape:
            return False, f"{k}: shape {n.shape} for {r.shape}"
        if r.dtype == bool or n.dtype == bool:
            if not np.array_equal(r.astype(bool), n.astype(bool)):
                return False, f"{k}: {int(np.sum(r.astype(bool) != n.astype(bool)))} flags differ"
            continue
        rn, nn = np.isnan(r), np.isnan(n)
        if not np.array_equal(rn, nn):
            return False, f"{k}: NaN at {int(np.sum(rn != nn))} other places"
        fin = ~rn & np.isfinite(r)
        if not np.array_equal(np.isinf(r), np.isinf(n)):
            return False, f"{k}: inf differs"
        if fin.any():
            scale = max(float(np.max(np.abs(r[fin]))), 1e-300)
            err = float(np.max(np.abs(r[fin] - n[fin]))) / scale
            if err > worst:
                worst, where = err, k
    return worst <= rtol, f"largest change {worst:.2e} of the field's scale in {where}" if where else "identical"


def _function(mutant: str) -> str:
    """``bayesrod.physics.elastica.x__balance__mutmut_7`` -> ``_balance``."""
    m = re.search(r"\.x_(.+)__mutmut_\d+$", mutant)
    if not m:
        raise ValueError(f"mutant: expected a mutmut name '<module>.x_<function>__mutmut_<n>', got {mutant!r}")
    return m.group(1)


def candidates(source: list[str], mutant: str, diff: list[str]) -> list[list[str]]:
    """Every way of applying ``diff`` (mutmut's -/+ lines) inside the mutated function of ``source``."""
    fname = _function(mutant)
    start = next((i for i, s in enumerate(source) if re.match(rf"def {re.escape(fname)}\(", s)), None)
    if start is None:
        return []
    end = next((i for i in range(start + 1, len(source)) if re.match(r"(def |class |@|\S)", source[i])), len(source))
    old = [d[1:] for d in diff if d.startswith("-")]
    new = [d[1:] for d in diff if d.startswith("+")]
    if not old:
        return []
    out = []
    for i in range(start, end - len(old) + 1):
        if [s.rstrip("\n") for s in source[i : i + len(old)]] == old:
            out.append(source[:i] + [s + "\n" for s in new] + source[i + len(old) :])
    return out


def _env(root: Path) -> dict:
    """A process that imports the bayesrod of the copy at ``root``, on one thread."""
    return {"PYTHONPATH": str(root), "OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "MPLBACKEND": "Agg"}


def _tests_fail(root: Path, tests: list[str], timeout: float) -> bool:
    """Do ``tests`` fail (or hang) on the tree at ``root``?"""
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-n0", "-p", "no:cacheprovider", "-m", "not slow", *tests]
    try:
        return subprocess.run(cmd, cwd=root, env=_env(root), capture_output=True, timeout=timeout).returncode != 0
    except subprocess.TimeoutExpired:
        return True


def _run(root: Path, out: Path, timeout: float, near_tip_only: bool = False) -> str:
    """The sweep with the copy at ``root``, saved to ``out``: "ok", "timeout" or "error: <last line>"."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--compute", str(out)]
    cmd += ["--near-tip-only"] if near_tip_only else []
    try:
        r = subprocess.run(cmd, env=_env(root), capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout"
    return "ok" if r.returncode == 0 else "error: " + (r.stderr.strip().splitlines() or ["?"])[-1][:200]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="?", help="scripts/mutation.py's JSON")
    ap.add_argument("--target", default="elastica_core")
    ap.add_argument("--out", help="the classes (JSON)")
    ap.add_argument("--compute", help="only run the sweep and save it here (.npz)")
    ap.add_argument("--rtol", type=float, default=1e-9)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--tests", nargs="*", default=[], help="test files run on each changed mutant")
    ap.add_argument("--near-tip-only", action="store_true", help="sweep only the friction stems near the tip")
    ap.add_argument(
        "--only-class",
        help="rerun only the survivors --out gave this class (e.g. same); writes <out>.<class>.rerun.json beside it",
    )
    args = ap.parse_args(argv)
    if args.compute:
        np.savez(args.compute, **compute(args.near_tip_only))
        return
    if not args.results or not args.out:
        ap.error("results and --out are needed (or --compute)")
    survivors = json.loads(Path(args.results).read_text())[args.target]["survivors"]
    out_path = Path(args.out)
    done = json.loads(out_path.read_text()) if out_path.exists() else {}  # resumable
    if args.only_class:  # a second, stricter sweep of what an earlier one left: its classes are redone
        survivors = {m: v for m, v in survivors.items() if done.get(m, {}).get("class") == args.only_class}
        out_path = out_path.with_name(out_path.stem + f".{args.only_class}.rerun.json")
        done = json.loads(out_path.read_text()) if out_path.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _copy_tree(tmp)
        target = tmp / MODULE
        original = target.read_text().splitlines(keepends=True)
        if _run(tmp, tmp / "ref.npz", args.timeout, args.near_tip_only) != "ok":
            raise SystemExit("the unmutated sweep failed")
        ref = dict(np.load(tmp / "ref.npz"))
        todo = [m for m in survivors if m not in done]
        for n, m in enumerate(todo, 1):
            ways = candidates(original, m, survivors[m]["diff"])
            if not ways:
                done[m] = {"class": "unapplied", "why": "the diff's lines are not in the function"}
            else:
                verdicts = []
                for way in ways:
                    target.write_text("".join(way))
                    status = _run(tmp, tmp / "new.npz", args.timeout, args.near_tip_only)
                    if status == "ok":
                        same, why = compare(ref, dict(np.load(tmp / "new.npz")), args.rtol)
                        cls = "same" if same else "changed"
                    else:
                        cls, why = ("timeout" if status == "timeout" else "error"), status
                    if cls != "same" and args.tests and _tests_fail(tmp, args.tests, 4 * args.timeout):
                        cls = "killed by the suite"
                    verdicts.append((cls, why))
                target.write_text("".join(original))
                # ambiguous diffs (the same line twice in the function): same only if every placement is
                cls = next((c for c, _ in verdicts if c != "same"), "same")
                done[m] = {"class": cls, "why": "; ".join(w for _, w in verdicts), "placements": len(ways)}
            tmp_out = out_path.with_suffix(".tmp")
            tmp_out.write_text(json.dumps(done, indent=1))
            tmp_out.replace(out_path)
            if sys.stderr.isatty():
                print(f"\r{n}/{len(todo)} {m}: {done[m]['class']}   ", end="", file=sys.stderr)
    print(json.dumps(Counter(v["class"] for v in done.values())), f"-> {out_path}")


if __name__ == "__main__":
    main()
