"""Render a report to PNG with headless Chromium (used for the README screenshot).

Usage::

    python -m reports.screenshot DIR/report.html [OUT.png] [--width 1400] [--height 4000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from reports.browser import ChromiumError, capture_png

__all__ = ["render_screenshot", "main"]


def render_screenshot(report: Path | str, png: Path | str | None = None, *, width: int = 1400,
                      height: int = 4000, chromium: str | None = None) -> Path:
    """Screenshot of the top ``width × height`` pixels of ``report`` after its plots rendered.

    ``png`` defaults to the report's path with the suffix ``.png``.
    """
    report = Path(report)
    out = Path(png) if png is not None else report.with_suffix(".png")
    return capture_png(report, out, width=width, height=height, chromium=chromium)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reports.screenshot",
                                     description="Render a solnic-bench report to PNG.")
    parser.add_argument("report", type=Path)
    parser.add_argument("png", type=Path, nargs="?")
    parser.add_argument("--width", type=int, default=1400)
    parser.add_argument("--height", type=int, default=4000)
    args = parser.parse_args(argv)
    try:
        out = render_screenshot(args.report, args.png, width=args.width, height=args.height)
    except (ChromiumError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
