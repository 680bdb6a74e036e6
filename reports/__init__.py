"""Self-contained HTML report of a solnic-bench run (SPEC §7).

Public API:

* :func:`build_report` — write ``out_dir/report.html`` from in-memory data;
* :func:`build_report_from_dir` — rebuild it from a run directory (layout in
  :mod:`reports.inputs`);
* :func:`reports.screenshot.render_screenshot` — PNG of a report via headless Chromium.
"""

from reports.build import REPORT_NAME, build_report, build_report_from_dir

__all__ = ["REPORT_NAME", "build_report", "build_report_from_dir"]
