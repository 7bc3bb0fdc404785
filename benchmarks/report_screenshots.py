"""The report pages of free_run, alsu and tvm430, as a user opens them: each system run in full,
`railcosim report` of it, report.html rendered by headless Chromium with every host name
unresolvable (so a page that needed the network would render empty), the screenshot written
to docs/figures/report_<system>.png. Prints per system the page's size and the receiver
errors by cause (the counts docs/scenarios.md quotes).

    python benchmarks/report_screenshots.py [--systems free_run alsu tvm430] [--keep DIR]

Needs Chromium (`apt-get install chromium`).
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
FIGURES = REPO / "docs" / "figures"


def screenshot(browser: str, page: Path, image: Path, height_px: int) -> None:
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    "--host-resolver-rules=MAP * ~NOTFOUND", f"--window-size=1400,{height_px}",
                    "--virtual-time-budget=10000", f"--screenshot={image}", page.as_uri()],
                   check=True, capture_output=True, timeout=180)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", default=["free_run", "alsu", "tvm430"])
    parser.add_argument("--keep", type=Path, help="run into this folder and keep it (default: a temporary one)")
    parser.add_argument("--height", type=int, default=1500, help="screenshot height in pixels (default 1500)")
    args = parser.parse_args()
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("report_screenshots: no chromium on PATH (apt-get install chromium)", file=sys.stderr)
        return 2
    from orchestrator.reports import chain_view
    from orchestrator.reports.report import read_results

    work = args.keep or Path(tempfile.mkdtemp(prefix="railcosim-report-"))
    FIGURES.mkdir(exist_ok=True)
    for system in args.systems:
        run = work / system
        for command in (["run", system, "--output", str(run), "--no-build"], ["report", str(run)]):
            subprocess.run([sys.executable, "-m", "orchestrator", *command], check=True, capture_output=True)
        summary = json.loads((run / "summary.json").read_text())
        metadata = json.loads((run / "metadata.json").read_text())
        causes: dict = {}
        for chain in chain_view.chains(read_results(run), summary, metadata["components"])[0]:
            for error in chain.errors:
                causes[error.cause] = causes.get(error.cause, 0) + error.count
        image = FIGURES / f"report_{system}.png"
        screenshot(browser, run / "report.html", image, args.height)
        size_mb = (run / "report.html").stat().st_size / 1e6
        print(f"{system}: report.html {size_mb:.2f} MB; receiver errors by cause {causes or 'none'}; "
              f"screenshot {image.relative_to(REPO)}")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
