"""The benchmark: closed-loop runs of every controller × scenario × seed, stored and reported.

* :mod:`bench.runner`, :mod:`bench.metrics` — one closed-loop run and its metrics (SPEC §3);
* :mod:`bench.scenarios` — built-in scenarios (thesis, quiet-friction, ratio-2);
* :mod:`bench.matrix` — the TOML matrix file → cells;
* :mod:`bench.cells` — one cell: config hash, :func:`~bench.cells.run_cell` (row + artifacts);
* :mod:`bench.series`, :mod:`bench.traces` — figure series from the report hooks; rerun recordings streamed
  to disk while a cell runs;
* :mod:`bench.isolation`, :mod:`bench.warm` — each cell in a fresh process watched from outside
  (death, hang, anything raised → an ``error`` row); the forkserver's kernel warm-up;
* :mod:`bench.executors` — local per-cell processes, dask.distributed;
* :mod:`bench.store`, :mod:`bench.driver` — atomic per-cell store, resume, rebuilt tables;
* :mod:`bench.aggregate`, :mod:`bench.provenance` — the terminal table, ``meta.json``;
* :mod:`bench.cli`, :mod:`bench.run_command`, :mod:`bench.list_command`, :mod:`bench.frontier` —
  bench's commands and what they share (the ``solnic-bench`` program that joins them with the
  report is :mod:`reports.cli`: bench never imports reports);
* :mod:`bench.bound` (a package: plan, cells, run, verdict, check, tables, command),
  :mod:`bench.hunting`, :mod:`bench.speed` (a package: config, sequence, contestants, accuracy,
  compare, comparison, tables, command) — the check of (2-6)/(2-1) and the speed comparison;
* :mod:`bench.tuning` — honest knob sweeps behind the controllers' defaults (docs/tuning.md).
"""
