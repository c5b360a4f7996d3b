"""Records: what a run directory holds, as typed records and column names (`RunSummary` and
its parts, `sysid.records.columns`), with the JSON record base (`JsonRecord`). Torch-free and
below the code that writes them (training, evaluation, `sysid.runs`): a reader of runs
(report, sweeps, tracking, maneuvers) needs only this layer and `sysid.runs.rundir`."""
