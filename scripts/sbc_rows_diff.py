"""Two SBC row files of the same seeds, replicate by replicate: what a code change moved.

    python scripts/sbc_rows_diff.py docs/results/sbc_geometry_seeds0-119_session60.csv OUT/sbc_geometry.csv

Reads two CSVs written by ``scripts/sbc_geometry.py`` (the same seeds fitted by two versions of the code) and
prints, for the seeds in both whose effect is fitted in each, every coverage that flipped and every rank that moved
by more than ``--rank-tol`` (of 99 posterior draws), then per parameter the count covered in each file and the
median |rank change| over the seeds refitted (rows where any parameter's median differs between the files;
identical rows, e.g. carried over from the old file, are counted apart). Two runs of the same posterior move a
rank among 99 independent draws by sd sqrt(2 x 99 F (1 - F)) (F the truth's posterior CDF): 7 at the centre, 4 at
F = 0.1, so moves of 10 are not yet evidence.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from sbc_geometry import PARAMS, _num

from bayesrod.dataset.io import read_rows


def _covered(r: dict, k: str) -> bool | None:
    v = str(r.get(f"{k}_covered", ""))
    return {"True": True, "1": True, "False": False, "0": False}.get(v)


def _rank(r: dict, k: str) -> float:
    return _num(r.get(f"{k}_rank"))


def diff(old: list[dict], new: list[dict], rank_tol: float = 10.0) -> str:
    """The report as text: flipped coverages and moved ranks, seed by seed, then the totals per parameter."""
    a = {int(r["seed"]): r for r in old}
    b = {int(r["seed"]): r for r in new}
    both = sorted(s for s in set(a) & set(b) if _covered(a[s], "EI0") is not None and _covered(b[s], "EI0") is not None)
    lines = [f"{len(both)} seeds fitted in both files ({len(set(a) ^ set(b))} in one only)", ""]
    same = 0
    moved: dict[str, list[float]] = {k: [] for k in PARAMS}
    identical = [s for s in both if all(a[s].get(f"{k}_median") == b[s].get(f"{k}_median") for k in PARAMS)]
    for s in both:
        notes = []
        for k in PARAMS:
            ca, cb = _covered(a[s], k), _covered(b[s], k)
            if ca is None or cb is None:
                continue
            d = _rank(b[s], k) - _rank(a[s], k)
            if s not in identical:
                moved[k].append(abs(d))
            if ca != cb:
                flip = "covered -> missed" if ca else "missed -> covered"
                notes.append(f"{k} {flip} (rank {_rank(a[s], k):.0f} -> {_rank(b[s], k):.0f})")
            elif abs(d) > rank_tol:
                notes.append(f"{k} rank {_rank(a[s], k):.0f} -> {_rank(b[s], k):.0f}")
        if notes:
            lines.append(
                f"seed {s} ({b[s]['effect']}, {b[s]['n_heights']} h, shapes {b[s]['shapes']}): " + "; ".join(notes)
            )
        else:
            same += 1
    lines += [
        "",
        f"{same} seeds with no flip and no rank moved by more than {rank_tol:g}; {len(identical)} rows identical",
        "",
    ]
    lines.append("| parameter | seeds | covered before | covered after | median abs rank change (refitted) |")
    lines.append("|---|---|---|---|---|")
    for k in PARAMS:
        sel = [s for s in both if _covered(a[s], k) is not None and _covered(b[s], k) is not None]
        if sel:
            before = sum(bool(_covered(a[s], k)) for s in sel)
            after = sum(bool(_covered(b[s], k)) for s in sel)
            med = f"{np.median(moved[k]):.0f} ({len(moved[k])})" if moved[k] else "-"
            lines.append(f"| {k} | {len(sel)} | {before} | {after} | {med} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--rank-tol", type=float, default=10.0)
    a = ap.parse_args(argv)
    print(diff(read_rows(a.old), read_rows(a.new), a.rank_tol))


if __name__ == "__main__":
    main()
