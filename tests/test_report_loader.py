"""Report building and loading: missing pieces, malformed files, self-containment, atomicity."""

from __future__ import annotations

import base64
import gzip
import json
import re

import numpy as np
import pandas as pd
import pytest

from reports import build_report, build_report_from_dir
from reports.browser import plot_render_status, static_external_references
from reports.inputs import SeriesRun, cell_id, load_inputs, write_series
from reports.synthetic import synthetic_inputs, write_synthetic_run

ALL_FIGURES = {"fig-peak-vs-current", "fig-peak-intervals", "fig-7-2", "fig-7-3", "fig-7-4", "fig-7-5",
               "fig-bound-omega", "fig-bound-lag", "fig-hunting", "fig-speed"}


def _figure_ids(html: str) -> set[str]:
    return set(plot_render_status(html))


def _claim_verdict(html: str, key: str) -> str:
    m = re.search(rf'<tr id="claim-{key}">.*?class="verdict ([a-z-]+)"', html, re.S)
    assert m, key
    return m.group(1)


def test_full_synthetic_run_renders_every_section(tmp_path):
    path = build_report_from_dir(write_synthetic_run(tmp_path / "run"))
    html = path.read_text(encoding="utf-8")
    assert path.name == "report.html"
    assert _figure_ids(html) == ALL_FIGURES
    assert "Not measured in this run:</strong> the" not in html
    assert "SYNTHETIC DATA" in html
    # One plotly.js bundle, inline; each figure only calls Plotly.newPlot.
    bundles = re.findall(r'<script id="plotly-bundle" type="application/gzip;base64">([^<]*)</script>', html)
    assert len(bundles) == 1
    assert gzip.decompress(base64.b64decode(bundles[0])).startswith(b"/**\n* plotly.js")
    assert html.count("Plotly.newPlot(") == len(ALL_FIGURES)
    for section in ("claims-table", "aggregate-table", "results-table", "hunting-table",
                    "speed-table", "bound-verdict", "config-json"):
        assert f'id="{section}"' in html, section
    assert "synthetic-0000000" in html  # the run's revision is shown


def test_report_is_self_contained(tmp_path):
    html = build_report_from_dir(write_synthetic_run(tmp_path)).read_text(encoding="utf-8")
    assert static_external_references(html) == []
    for pattern in (r'<script[^>]+src=', r'<link[^>]+href=', r'<img[^>]+src=', r'@import',
                    r'<iframe'):
        # Only outside of script text: strip the inline scripts first.
        body = re.sub(r"<script>.*?</script>", "", html, flags=re.S)
        assert not re.search(pattern, body, re.I), pattern


def test_static_reference_checker_catches_network_loads():
    leaky = ('<html><head><link rel="stylesheet" href="https://cdn.example/x.css">'
             '<style>body{background:url(http://x.example/a.png)} @import "y.css";</style>'
             '<script src="//cdn.example/plotly.js"></script></head><body>'
             '<img src="data:image/png;base64,AAAA"><img srcset="pic.png 2x">'
             '<a href="#top">ok</a><script>var s = "<img src=\'https://not.loaded\'>";</script>'
             '</body></html>')
    refs = static_external_references(leaky)
    joined = "\n".join(refs)
    assert "https://cdn.example/x.css" in joined
    assert "http://x.example/a.png" in joined
    assert "@import" in joined
    assert "//cdn.example/plotly.js" in joined
    assert "pic.png" in joined
    assert "not.loaded" not in joined  # script text is not markup
    assert "data:image" not in joined and "#top" not in joined


def test_empty_directory_renders_not_measured_everywhere(tmp_path):
    html = build_report_from_dir(tmp_path).read_text(encoding="utf-8")
    assert _figure_ids(html) == set()
    for what in ("the benchmark matrix", "peak error vs average current",
                 "Figure 7-2", "Figure 7-5", "the empirical check of (2-6)",
                 "the hunting onset", "the speed comparison", "the configuration"):
        assert f"<strong>Not measured in this run:</strong> {what}" in html, what
    assert "No meta.json" in html and "No config.json" in html
    # Only the two analytic claims have verdicts; everything measured is "not measured".
    assert _claim_verdict(html, "classical_limit") == "reproduced"
    assert _claim_verdict(html, "peak_medium") == "not-measured"
    assert _claim_verdict(html, "speedup") == "not-measured"
    assert "PlantParams defaults" in html  # the limit's parameters are labelled as defaults


def test_results_csv_only(tmp_path):
    d = synthetic_inputs()
    d["results"].drop(columns=["rms_current", "cell"]).to_csv(tmp_path / "results.csv",
                                                              index=False)
    (tmp_path / "config.json").write_text(json.dumps(d["config"]))
    html = build_report_from_dir(tmp_path).read_text(encoding="utf-8")
    assert _figure_ids(html) == {"fig-peak-vs-current", "fig-peak-intervals"}
    assert "<strong>Not measured in this run:</strong> rms_current" in html
    assert "<strong>Not measured in this run:</strong> Figure 7-4" in html
    assert _claim_verdict(html, "less_current") == "reproduced"
    assert _claim_verdict(html, "ks_at_54") == "not-measured"


def test_loader_attributes_series_to_results_rows(tmp_path):
    write_synthetic_run(tmp_path)
    inputs = load_inputs(tmp_path)
    run = inputs.series[cell_id("solnic", "thesis", 0)]
    assert (run.controller, run.scenario, run.seed) == ("solnic", "thesis", 0)
    assert inputs.bound["stable"].dtype == bool
    assert inputs.notes == ()


def test_errors_shown_in_microradians(tmp_path):
    res = pd.DataFrame([dict(controller="linear", scenario="thesis", seed=0, status="ok",
                             peak_error_rad=12.5e-6, mean_abs_current=1.0)])
    html = build_report(tmp_path, results=res, config={}, meta={}).read_text(encoding="utf-8")
    assert re.search(r'<td data-v="12\.5" class="num">12\.5</td>', html)


def test_in_memory_series_and_typical_cell(tmp_path):
    d = synthetic_inputs(series_seeds=(0, 1))
    d["config"]["report"] = {"typical_cell": cell_id("solnic", "thesis", 1)}
    html = build_report(tmp_path, **d).read_text(encoding="utf-8")
    assert "solnic__thesis__s1</code>" in html
    d["config"]["report"] = {"typical_cell": "nope"}
    with pytest.raises(ValueError, match="typical_cell 'nope'"):
        build_report(tmp_path, **d)
    frame = d["series"][cell_id("solnic", "thesis", 0)]
    run = SeriesRun("custom", frame, "solnic", "thesis", 7)
    d["config"].pop("report")
    html = build_report(tmp_path, results=d["results"], series={"custom": run},
                        config=d["config"], meta={}).read_text(encoding="utf-8")
    assert "fig-7-4" in _figure_ids(html)


def test_missing_directory_raises(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        build_report_from_dir(tmp_path / "nope")


@pytest.mark.parametrize("name, content, match", [
    ("bound.csv", "design,omega_c\nd,1\n", r"bound\.csv is missing required column"),
    ("hunting.csv", "ks_over_kc,lmax\n1.5,6\n", r"hunting\.csv is missing required column.*onset_L"),
    ("speed.json", json.dumps({"rows": [{"method": "m", "setting": "s", "error": 1}]}),
     r"speed\.json rows\[0\] is missing key"),
    ("config.json", "{not json", r"config\.json is not valid JSON"),
    ("results.csv", "controller,scenario,seed\nlinear,thesis,0\n",
     r"results is missing required column.*status"),
])
def test_malformed_files_name_the_file_and_column(tmp_path, name, content, match):
    (tmp_path / name).write_text(content)
    with pytest.raises(ValueError, match=match):
        build_report_from_dir(tmp_path)


def test_bound_booleans_are_validated(tmp_path):
    b = synthetic_inputs()["bound"].head(3).copy()
    b["stable"] = ["yes", "maybe", "no"]
    b.to_csv(tmp_path / "bound.csv", index=False)
    with pytest.raises(ValueError, match="'stable' must be boolean"):
        build_report_from_dir(tmp_path)


def test_write_is_atomic_and_replaces(tmp_path):
    write_synthetic_run(tmp_path)
    (tmp_path / "report.html").write_text("old")
    build_report_from_dir(tmp_path)
    assert (tmp_path / "report.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    # A failing build leaves the previous report untouched and no temporary file behind.
    (tmp_path / "speed.json").write_text("[]")
    with pytest.raises(ValueError):
        build_report_from_dir(tmp_path)
    assert (tmp_path / "report.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".tmp"] == []


def test_failed_cells_are_listed_but_not_aggregated(tmp_path):
    res = pd.DataFrame([
        dict(controller="linear", scenario="thesis", seed=0, status="ok", peak_error_rad=8e-6),
        dict(controller="linear", scenario="thesis", seed=1, status="chatter",
             message="event guard", peak_error_rad=np.nan)])
    html = build_report(tmp_path, results=res, config={}, meta={}).read_text(encoding="utf-8")
    assert "event guard" in html
    assert '<td data-v="0.5" class="num bad">1 / 2</td>' in html


def test_interrupted_write_leaves_old_report_and_no_temp(tmp_path, monkeypatch):
    import bench.store as store   # the report is written by the store's atomic writer

    (tmp_path / "report.html").write_text("old")

    def boom(src, dst):
        raise OSError("disk full")
    monkeypatch.setattr(store.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        build_report(tmp_path, results=None, config={}, meta={})
    assert (tmp_path / "report.html").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_write_series_round_trip_and_validation(tmp_path):
    frame = pd.DataFrame({"t": [0.0, 0.01, 0.02], "x1": [0.0, 1e-6, -1e-6],
                          "ks_hat_pct": [50.0, 60.0, 70.0]})
    path = write_series(tmp_path, "solnic__thesis__3", frame)
    assert path == tmp_path / "series" / "solnic__thesis__3.parquet"
    run = load_inputs(tmp_path).series["solnic__thesis__3"]
    assert (run.controller, run.scenario, run.seed) == ("solnic", "thesis", 3)
    pd.testing.assert_frame_equal(run.frame, frame)
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['ks_hat'\]"):
        write_series(tmp_path, "c", frame.rename(columns={"ks_hat_pct": "ks_hat"}))
    with pytest.raises(ValueError, match="non-decreasing"):
        write_series(tmp_path, "c", frame.iloc[::-1])
    with pytest.raises(ValueError, match="plain file name"):
        write_series(tmp_path, "../c", frame)


def test_only_the_series_the_report_reads_are_loaded(tmp_path):
    """A frontier run stores thousands of series; the loader reads the identification
    controller's own thesis series (the claims), the typical run and unattributed files only,
    and the claims come out the same as with every series in memory."""
    from reports.claims import Selection, evaluate_claims
    from reports.inputs import attribute_series
    from reports.limits import limits_from_config

    write_synthetic_run(tmp_path, series_seeds=(0, 1))
    frame = pd.read_parquet(tmp_path / "series" / f"{cell_id('solnic', 'thesis', 0)}.parquet")
    unused = [cell_id("solnic", "quiet-friction", 0), cell_id("solnic-high-cost", "thesis", 0),
              cell_id("linear", "thesis", 1)]
    for cell in [*unused, "orphan__thesis__s9"]:
        frame.to_parquet(tmp_path / "series" / f"{cell}.parquet", index=False)
    inputs = load_inputs(tmp_path)
    assert set(inputs.series) == {cell_id("solnic", "thesis", 0), cell_id("solnic", "thesis", 1),
                                  "orphan__thesis__s9"}
    every = attribute_series({p.stem: pd.read_parquet(p) for p in (tmp_path / "series").glob("*.parquet")},
                             inputs.results)
    assert len(every) == 6
    limits, sel = limits_from_config(inputs.config), Selection.from_config(inputs.config)
    claims = [evaluate_claims(results=inputs.results, limits=limits, series=s, bound=inputs.bound,
                              hunting=inputs.hunting, speed=inputs.speed, selection=sel, warmup_s=20.0)
              for s in (inputs.series, every)]
    assert [(r.key, r.measured, r.verdict, r.basis) for r in claims[0]] == \
        [(r.key, r.measured, r.verdict, r.basis) for r in claims[1]]
    # a configured typical cell is read even when no claim uses it
    config = json.loads((tmp_path / "config.json").read_text())
    config["report"] = {"typical_cell": unused[2]}
    (tmp_path / "config.json").write_text(json.dumps(config))
    assert unused[2] in load_inputs(tmp_path).series
