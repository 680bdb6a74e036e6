"""The report in a real browser: every plotly figure renders and the page makes no request.

Runs Debian's headless Chromium (``/usr/bin/chromium``; ``.ci/run`` installs it). Without
Chromium the tests skip locally and FAIL when the environment variable ``CI`` is set.

How it checks
-------------
* Rendering: ``--dump-dom`` after a virtual-time budget gives the DOM once the scripts ran;
  each ``div.plotly-graph-div`` must hold plotly's ``svg.main-svg``, and the page's own error
  log (``#report-js-errors``, fed by ``window.onerror`` and a post-load self-check) is empty.
* Network: the same run writes a NetLog (``--log-net-log``). Every request made on behalf of the
  page must be ``file:``/``data:``; Chromium's own background pings (initiator "not an origin")
  are not the page's and are reported separately. A deliberately leaky control page proves the
  NetLog check sees page loads. The HTML is also checked statically for network references.
* A screenshot (1400×4000) is saved in the test's tmp dir.
"""

from __future__ import annotations

import os
import re
import struct

import pytest

from reports import build_report_from_dir
from reports.browser import (dump_dom, find_chromium, netlog_requests, page_network_requests,
                             plot_render_status, static_external_references)
from reports.screenshot import render_screenshot
from reports.synthetic import write_synthetic_run

EXPECTED_FIGURES = {"fig-peak-vs-current", "fig-peak-intervals", "fig-7-2", "fig-7-3", "fig-7-4", "fig-7-5",
                    "fig-bound-omega", "fig-bound-lag", "fig-hunting", "fig-speed"}


@pytest.fixture(scope="module")
def chromium() -> str:
    path = find_chromium()
    if path is None:
        reason = ("Chromium not installed (apt-get install chromium, or set "
                  "SOLNIC_BENCH_CHROMIUM)")
        if os.environ.get("CI"):
            pytest.fail(f"{reason}; required in CI")
        pytest.skip(reason)
    return path


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    run = write_synthetic_run(tmp_path_factory.mktemp("report-run"))
    return build_report_from_dir(run)


@pytest.fixture(scope="module")
def rendered(chromium, report, tmp_path_factory):
    netlog = tmp_path_factory.mktemp("netlog") / "netlog.json"
    dom = dump_dom(report, netlog=netlog, chromium=chromium)
    return dom, netlog


def test_every_plot_renders(rendered):
    dom, _ = rendered
    status = plot_render_status(dom)
    assert set(status) == EXPECTED_FIGURES
    assert all(status.values()), {k: v for k, v in status.items() if not v}
    # The page's post-load self-check ran and found no script error and no undrawn figure.
    assert re.search(r'<body[^>]*data-report-checked="0"', dom)
    errors = re.search(r'<pre id="report-js-errors">(.*?)</pre>', dom, re.S)
    assert errors is not None and errors.group(1).strip() == ""
    assert 'id="report-js-error-banner" style="display: block' not in dom


def test_page_makes_no_network_request(rendered, report):
    _, netlog = rendered
    assert netlog.is_file() and netlog.stat().st_size > 0
    assert page_network_requests(netlog) == []
    # The browser's own traffic is never attributed to the page's file:// site.
    for req in netlog_requests(netlog):
        assert "file://" not in req.isolation_key or req.url.startswith(("file:", "data:"))
    assert static_external_references(report.read_text(encoding="utf-8")) == []


def test_network_check_catches_a_leaky_page(chromium, tmp_path):
    page = tmp_path / "leaky.html"
    page.write_text('<!DOCTYPE html><html><head>'
                    '<script src="https://cdn.example.invalid/plotly.min.js"></script></head>'
                    '<body><img src="http://img.example.invalid/x.png">'
                    '<img src="data:image/gif;base64,R0lGODlhAQABAAAAACw="></body></html>')
    netlog = tmp_path / "netlog.json"
    dump_dom(page, netlog=netlog, chromium=chromium, budget_ms=3000)
    urls = {r.url for r in page_network_requests(netlog)}
    assert "https://cdn.example.invalid/plotly.min.js" in urls
    assert "http://img.example.invalid/x.png" in urls
    assert not any(u.startswith("data:") for u in urls)


def test_screenshot(chromium, report, tmp_path):
    png = render_screenshot(report, tmp_path / "report.png", width=1400, height=4000,
                            chromium=chromium)
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    assert (width, height) == (1400, 4000)
    assert len(data) > 100_000  # a page with text and a plot, not a blank canvas


def test_tables_sort_on_header_click(chromium, report, tmp_path):
    # Click "peak mean" of the aggregate table twice (ascending, then descending) after load.
    html = report.read_text(encoding="utf-8")
    click = ('<script>window.addEventListener("load", function () {'
             'var th = document.querySelector("#aggregate-table thead th:nth-child(4)");'
             'th.click(); var asc = Array.prototype.map.call('
             'document.querySelectorAll("#aggregate-table tbody td:nth-child(4)"),'
             'function (td) { return td.getAttribute("data-v"); });'
             'th.click(); document.body.setAttribute("data-asc", asc.join(" "));'
             '});</script></body>')
    page = tmp_path / "report_click.html"
    page.write_text(html.replace("</body>", click), encoding="utf-8")
    dom = dump_dom(page, chromium=chromium)
    asc = [float(v) for v in re.search(r'data-asc="([^"]*)"', dom).group(1).split()]
    assert len(asc) > 3 and asc == sorted(asc)
    table = re.search(r'<table class="sortable" id="aggregate-table">(.*?)</table>', dom, re.S)
    desc = [float(v) for v in re.findall(
        r'<tr>(?:<td[^>]*>.*?</td>){3}<td data-v="([^"]+)"', table.group(1))]
    assert desc == sorted(asc, reverse=True)


def test_answer_block_names_the_lowest_median_of_results_csv(rendered, report):
    """The rendered answer (after the browser ran the page's scripts) names, per scenario, the
    controller with the lowest median peak error in the run's results.csv among those that are
    no privileged bound and finished ok on every seed of the scenario."""
    import pandas as pd

    dom, _ = rendered
    csv = report.parent / "results.csv"
    res = pd.read_csv(csv) if csv.exists() else pd.read_parquet(report.parent / "results.parquet")
    complete = res.groupby(["scenario", "controller"])["status"].transform(lambda s: (s == "ok").all())
    ok = res[complete]
    if "privileged" in ok.columns:
        ok = ok[~ok["privileged"].astype(str).str.lower().eq("true")]
    assert not ok.empty
    for scen, g in ok.groupby("scenario"):
        medians = g.groupby("controller")["peak_error_rad"].median()
        row = re.search(rf'<tr id="answer-{re.escape(scen)}"[^>]*>(.*?)</tr>', dom, re.S)
        assert row, scen
        named = re.search(r'<td class="best">([^<(]*)', row.group(1)).group(1).strip()
        assert medians.idxmin() in [n.strip() for n in named.split("=")], (scen, named)
    # the sticky table of contents stays in view
    assert re.search(r'<nav class="toc" id="toc">', dom)
