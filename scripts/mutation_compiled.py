"""Mutation testing of the compiled RK step (bayesrod/physics/_compiled.py), which mutmut cannot reach.

mutmut (scripts/mutation.py) runs each mutant through a Python trampoline, which numba cannot compile; and
mutation.py runs with ``BAYESROD_NO_JIT=1`` so that mutants of elastica.py's numpy steps are what the tests run.
This script makes the single-token mutants of the compiled module itself, from its syntax tree: every
arithmetic operator swapped (+ -, * /, ** *), every comparison loosened or flipped (< <=, > >=, == !=), every
numeric constant changed (0 -> 1, x -> x + 1, 1e-300 -> 1e-200), every unary minus dropped, every ``not``
dropped, every ``and``/``or`` swapped and every conditional expression's branches swapped, inside the functions
(not docstrings). Each mutant is written into a copy of the tracked tree, compiled afresh (its own
``NUMBA_CACHE_DIR``) and run against ``--tests`` (default: the step tests of tests/test_elastica.py, which compare
the loop with the numpy steps); a survivor is run again against ``--suite`` (the physics test files whole).
Killed: a test fails, the mutant does not compile, or it runs over ``--timeout``.

Usage::

    python scripts/mutation_compiled.py --out docs/results/mutation_compiled.json
    python scripts/mutation_compiled.py --list            # the mutants, without running them

The result (JSON): per mutant its line, the change, and ``killed`` / ``killed by the suite`` / ``survived``;
docs/validation.md holds the latest counts and a line on every survivor.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutation import ROOT, _copy_tree  # noqa: E402  (the same copy of the tracked tree mutmut's runs use)

MODULE = "bayesrod/physics/_compiled.py"
TESTS = ["tests/test_elastica.py", "-k", "step"]
SUITE = ["tests/test_elastica.py", "tests/test_elastica_core.py", "tests/test_slip.py"]

_SWAPS = {
    ast.Add: ast.Sub,
    ast.Sub: ast.Add,
    ast.Mult: ast.Div,
    ast.Div: ast.Mult,
    ast.Pow: ast.Mult,
    ast.Lt: ast.LtE,
    ast.LtE: ast.Lt,
    ast.Gt: ast.GtE,
    ast.GtE: ast.Gt,
    ast.Eq: ast.NotEq,
    ast.NotEq: ast.Eq,
    ast.And: ast.Or,
    ast.Or: ast.And,
}


def _docstring_nodes(tree: ast.AST) -> set[int]:
    """ids of the docstring constants (not mutated)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.FunctionDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def _in_functions(tree: ast.Module) -> list[ast.AST]:
    """Every node inside the module's function bodies, in source order."""
    nodes = []
    for fn in tree.body:
        if isinstance(fn, ast.FunctionDef) and fn.name not in ("_load_numba", "_jit"):
            for stmt in fn.body:
                nodes.extend(ast.walk(stmt))
    return nodes


def _mutations(source: str) -> list[tuple[int, str, callable]]:
    """(line, description, apply) for every single-token mutant; ``apply`` edits a fresh tree in place."""
    tree = ast.parse(source)
    skip = _docstring_nodes(tree)
    found = []
    for k, node in enumerate(_in_functions(tree)):
        if id(node) in skip:
            continue
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.BinOp | ast.BoolOp) and type(node.op) in _SWAPS:
            new = _SWAPS[type(node.op)]
            found.append((line, f"{type(node.op).__name__} -> {new.__name__}", (k, "op", new)))
        elif isinstance(node, ast.AugAssign) and type(node.op) in _SWAPS:
            new = _SWAPS[type(node.op)]
            found.append((line, f"{type(node.op).__name__}= -> {new.__name__}=", (k, "op", new)))
        elif isinstance(node, ast.Compare):
            for i, op in enumerate(node.ops):
                if type(op) in _SWAPS:
                    new = _SWAPS[type(op)]
                    found.append((line, f"{type(op).__name__} -> {new.__name__}", (k, "cmp", (i, new))))
        elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
            v = node.value
            new_v = 1e-200 if v == 1e-300 else (type(v)(1) if v == 0 else v + 1)
            found.append((line, f"{v!r} -> {new_v!r}", (k, "const", new_v)))
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.Not):
            found.append((line, f"drop {type(node.op).__name__}", (k, "unary", None)))
        elif isinstance(node, ast.IfExp):
            found.append((line, "swap the branches of x if c else y", (k, "ifexp", None)))
    return found


def _apply(source: str, where: tuple) -> str:
    k, kind, arg = where
    tree = ast.parse(source)
    nodes = _in_functions(tree)
    node = nodes[k]
    if kind == "op":
        node.op = arg()
    elif kind == "cmp":
        i, new = arg
        node.ops[i] = new()
    elif kind == "const":
        node.value = arg
    elif kind == "ifexp":
        node.body, node.orelse = node.orelse, node.body
    elif kind == "unary":
        # replace the UnaryOp by its operand: find its parent
        for parent in ast.walk(tree):
            for field, value in ast.iter_fields(parent):
                if value is node:
                    setattr(parent, field, node.operand)
                elif isinstance(value, list) and any(v is node for v in value):
                    setattr(parent, field, [node.operand if v is node else v for v in value])
    return ast.unparse(ast.fix_missing_locations(tree))


def _run(tree: Path, tests: list[str], timeout: float) -> bool:
    """True when the tests fail (the mutant is killed)."""
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPATH": str(tree)}
    env.pop("BAYESROD_NO_JIT", None)
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        try:
            res = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", "-x", "-n0", "-p", "no:cacheprovider", *tests],
                cwd=tree,
                env=env,
                capture_output=True,
                timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            return True
    return res.returncode != 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="JSON of every mutant and its fate")
    ap.add_argument("--list", action="store_true", help="list the mutants and stop")
    ap.add_argument("--timeout", type=float, default=300.0)
    args = ap.parse_args()
    source = (ROOT / MODULE).read_text()
    muts = _mutations(source)
    if args.list:
        for line, desc, _ in muts:
            print(f"{line:4d}  {desc}")
        print(f"{len(muts)} mutants")
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp)
        _copy_tree(tree)
        target = tree / MODULE
        # the unmutated module, unparsed the same way, must pass (else every mutant would be "killed")
        target.write_text(ast.unparse(ast.parse(source)))
        if _run(tree, TESTS, args.timeout):
            raise SystemExit("the unmutated module fails the tests: nothing to measure")
        t0 = time.time()
        for n, (line, desc, where) in enumerate(muts, 1):
            target.write_text(_apply(source, where))
            fate = "killed" if _run(tree, TESTS, args.timeout) else None
            if fate is None:
                fate = "killed by the suite" if _run(tree, SUITE, args.timeout * 4) else "survived"
            rows.append({"line": line, "change": desc, "fate": fate})
            print(f"[{n}/{len(muts)} {time.time() - t0:.0f} s] line {line}: {desc}: {fate}", file=sys.stderr)
    counts = {f: sum(r["fate"] == f for r in rows) for f in ("killed", "killed by the suite", "survived")}
    print(json.dumps(counts))
    for r in rows:
        if r["fate"] == "survived":
            print(f"survived: line {r['line']}: {r['change']}")
    if args.out:
        tmp_out = args.out.with_suffix(args.out.suffix + ".tmp")
        tmp_out.write_text(json.dumps({"module": MODULE, "counts": counts, "mutants": rows}, indent=1))
        os.replace(tmp_out, args.out)


if __name__ == "__main__":
    main()
