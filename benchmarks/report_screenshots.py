"""Time the report build, render the PDF to PNG pages and screenshot the HTML page.

    python benchmarks/report_screenshots.py [RUN_OR_REPRODUCE_DIR] [--pages 1-6] [--height 6000]

Without a directory, a synthetic reproduction directory (tests/synthetic_rundir.py, full
scenario lengths) is written first. Needs poppler-utils (pdftoppm) and Debian's chromium.
Prints the temporary directory holding report.html, report.pdf, page-NN.png and
html.png; nothing is written into the repository.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def chromium_screenshot(html: Path, png: Path, width: int, height: int) -> None:
    """Headless Debian chromium, isolated profile, no network services."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        print("chromium not found: skipping the HTML screenshot")
        return
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                        "--no-first-run", "--disable-background-networking", "--disable-component-update",
                        "--disable-sync", f"--user-data-dir={profile}", f"--screenshot={png}",
                        f"--window-size={width},{height}", "--hide-scrollbars", html.resolve().as_uri()],
                       check=True, timeout=180, capture_output=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", nargs="?", help="run or reproduction directory (default: synthetic)")
    parser.add_argument("--pages", default="", help="PDF pages to render, e.g. 1-6 (default all)")
    parser.add_argument("--height", type=int, default=6000, help="HTML screenshot height [px]")
    parser.add_argument("--dpi", type=int, default=80)
    args = parser.parse_args()

    from sysid.report import build_report
    work = Path(tempfile.mkdtemp(prefix="sysid_report_shots_"))
    source = Path(args.source) if args.source else None
    if source is None:
        sys.path.insert(0, str(ROOT / "tests"))
        from synthetic_rundir import write_reproduction
        t0 = time.perf_counter()
        source = write_reproduction(work / "synthetic")
        print(f"synthetic reproduction written in {time.perf_counter() - t0:.1f} s: {source}")
    t0 = time.perf_counter()
    paths = build_report(source, work)
    print(f"report built in {time.perf_counter() - t0:.1f} s: {paths.n_figures} figures, "
          f"{paths.n_pages} pages, notes: {paths.notes or 'none'}")
    if shutil.which("pdftoppm"):
        cmd = ["pdftoppm", "-png", "-r", str(args.dpi)]
        if args.pages:
            first, _, last = args.pages.partition("-")
            cmd += ["-f", first, "-l", last or first]
        subprocess.run(cmd + [str(paths.pdf), str(work / "page")], check=True)
    else:
        print("pdftoppm not found: skipping the PDF pages")
    chromium_screenshot(paths.html, work / "html.png", 1280, args.height)
    print(f"output in {work}")
    for png in sorted(work.glob("*.png")):
        print(f"  {png.name}")


if __name__ == "__main__":
    main()
