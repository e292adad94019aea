"""The trials file, as the studies export it; its home is :mod:`vibrofocus.io.trials_csv`."""

from ..io.trials_csv import (
    MODEL_COLUMN,
    ONSET_COLUMNS,
    POINT_COLUMNS,
    PROTOCOL_COLUMNS,
    SESSION_COLUMNS,
    SIMULATED_COLUMN,
    STIMULUS_COLUMNS,
    TRIALS_COLUMNS,
    read_trials_csv,
    write_trials_csv,
)

__all__ = ["TRIALS_COLUMNS", "SESSION_COLUMNS", "ONSET_COLUMNS", "STIMULUS_COLUMNS", "PROTOCOL_COLUMNS", "POINT_COLUMNS",
           "SIMULATED_COLUMN", "MODEL_COLUMN", "write_trials_csv", "read_trials_csv"]
