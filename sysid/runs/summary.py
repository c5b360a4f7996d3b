"""summary.json of a run directory: `RunSummary` and its parts live in `sysid.records.summary`
(below the code that writes them); their names stay importable here."""
from sysid.records.summary import (LEGACY_VAL_LOSS, VAL_LOSS_DEFINITION, DataSummary,  # noqa: F401
                                   GateSummary, IdentificationSummary, LogFile, RunSummary, SplitFile,
                                   SplitSummary, StartStateCheckSummary, TrainingDetails, UncertaintySummary,
                                   VerdictCell, VerdictSummary, WeakDirection)
