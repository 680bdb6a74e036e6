"""Self-contained HTML report of a solnic-bench run (SPEC §7).

Public API:

* :func:`build_report` — write ``out_dir/report.html`` from in-memory data;
* :func:`build_report_from_dir` — rebuild it from a run directory (layout in
  :mod:`reports.inputs`);
* :func:`reports.screenshot.render_screenshot` — PNG of a report via headless Chromium;
* :mod:`reports.cli` — the ``solnic-bench`` command line (bench's commands and the report).

The names above are loaded on first use (PEP 562), so that ``solnic-bench``, whose entry point
is in this package, starts without plotly and jinja2 until it builds a report.
"""

from __future__ import annotations

from typing import Any

__all__ = ["REPORT_NAME", "build_report", "build_report_from_dir"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from reports import build
        return getattr(build, name)
    raise AttributeError(f"module 'reports' has no attribute {name!r}")
