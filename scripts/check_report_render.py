"""Render a run's report.html in headless Chromium and check that the figures show.

    python scripts/check_report_render.py RUN/report.html [--out shot.png]

Takes a full-page screenshot with Debian's ``chromium`` (``apt install chromium``)
and a second one with every embedded figure replaced by a blank box. The figures
must add coloured pixels over at least 0.02% of the page per figure (measured:
0.19% for the 4 figures of a fit report, 0.005% when the images are broken).
Exit 0 when the report renders with its figures, 1 otherwise, 2 when Chromium
is missing.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot(html: Path, png: Path, width: int = 1200, height: int = 2600) -> np.ndarray:
    exe = chromium()
    if exe is None:
        raise FileNotFoundError("chromium: expected Debian's chromium on PATH, got none (apt install chromium)")
    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", f"--window-size={width},{height}"]
    cmd += [f"--screenshot={png}", html.resolve().as_uri()]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    import cv2

    img = cv2.imread(str(png))
    if img is None:
        raise RuntimeError(f"{png}: chromium wrote no screenshot")
    return img


def check(report: Path, out: Path | None = None) -> dict:
    text = report.read_text()
    n_fig = len(re.findall(r"<img ", text))
    with tempfile.TemporaryDirectory() as tmp:
        shot = screenshot(report, out or Path(tmp) / "shot.png")
        blank_html = Path(tmp) / "blank.html"
        blank_html.write_text(
            re.sub(
                r'<img [^>]*src="data:image/png;base64,[^"]*">',
                '<div style="width:520px;height:340px;display:inline-block"></div>',
                text,
            )
        )
        blank = screenshot(blank_html, Path(tmp) / "blank.png")
    ink = float(np.mean(shot.min(axis=2) < 200))
    # figures bring colour (bands, data, contours); text, tables and broken-image icons hardly any
    colour = float(np.mean(np.ptp(shot.astype(int), axis=2) > 50))
    colour_blank = float(np.mean(np.ptp(blank.astype(int), axis=2) > 50))
    gain = colour - colour_blank
    ok = n_fig >= 1 and ink > 0.01 and gain > 0.0002 * n_fig
    return {"figures": n_fig, "ink_fraction": ink, "colour_from_figures": gain, "ok": ok}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("report", type=Path)
    ap.add_argument("--out", type=Path, help="keep the screenshot here")
    a = ap.parse_args()
    if chromium() is None:
        print("chromium not found (apt install chromium)", file=sys.stderr)
        return 2
    res = check(a.report, a.out)
    print(res)
    return 0 if res["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
