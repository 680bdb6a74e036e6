"""``python -m reports DIR`` — (re)build ``DIR/report.html`` from a run directory.

Options: ``--synthetic`` first writes synthetic demo inputs into DIR (layout preview only; the
report is bannered as synthetic); ``--screenshot PNG`` also renders the page to PNG.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from reports.browser import ChromiumError
from reports.build import build_report_from_dir
from reports.screenshot import render_screenshot
from reports.synthetic import write_synthetic_run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reports", description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--synthetic", action="store_true",
                        help="write synthetic demo inputs into RUN_DIR first")
    parser.add_argument("--screenshot", type=Path, metavar="PNG")
    args = parser.parse_args(argv)
    if args.synthetic:
        write_synthetic_run(args.run_dir)
    try:
        path = build_report_from_dir(args.run_dir)
        print(path)
        if args.screenshot:
            print(render_screenshot(path, args.screenshot))
    except (FileNotFoundError, ValueError, ChromiumError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
