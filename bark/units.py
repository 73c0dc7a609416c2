"""The model's units, from the paper's calibration ("Growth simulation"): stated once, used everywhere.

1 time unit = 88.5 days (about 412.5 leaves a year and 10–20 mm of trunk a year); 1 length unit =
0.3 m.  Everything inside bark is in model units; these convert for people (progress, figures).
"""

from __future__ import annotations

import numpy as np

DAYS_PER_TIME_UNIT = 88.5
METRES_PER_LENGTH_UNIT = 0.3
DAYS_PER_YEAR = 365.25

__all__ = ["DAYS_PER_TIME_UNIT", "METRES_PER_LENGTH_UNIT", "COLUMN_UNITS", "headed", "data_frame", "years", "metres",
           "unwrap"]

COLUMN_UNITS = {"t": "tu", "radius": "lu", "z": "lu", "lambda1": "lu2", "lambda2": "lu2", "tension": "fu",
                "dissipation": "fu_lu_per_tu"}
"""The unit a table column carries in its name (CSV files and DataFrames): ``tu`` time units, ``lu``
length units, ``lu2`` length units squared, ``fu`` force units (a spring's ``k`` is in force units per
length unit), ``fu_lu_per_tu`` power; a name ending ``_deg`` is in degrees, and a name with no unit is
a count, an index or a pure number.  In memory (``arrays()``, ``rows()``) the columns go by their
short names."""


def headed(columns, units: dict[str, str] = COLUMN_UNITS) -> list[str]:
    """A table's header: each column's short name with its unit (:data:`COLUMN_UNITS`) appended,
    ``t`` → ``t_tu``; a column with no unit as it is."""
    return [f"{c}_{units[c]}" if c in units else c for c in columns]


def data_frame(rows, columns, header=None):
    """``pandas.DataFrame(rows, columns=columns)`` headed ``header`` (default: ``columns``), or one
    line saying pandas is needed (it is not a dependency of bark).  ``rows`` are dicts, or a dict of
    equal-length columns."""
    from bark.errors import BarkError

    try:
        import pandas
    except ImportError:
        raise BarkError("pandas is needed for a DataFrame (pip install pandas); the rows are there without it") from None
    frame = pandas.DataFrame(rows, columns=columns)
    if header is not None:
        frame.columns = list(header)
    return frame


def years(t):
    """Simulated time ``t`` (time units) in years (a time unit is 88.5 days).

    >>> round(years(412.5), 1)
    99.9
    """
    return t * (DAYS_PER_TIME_UNIT / DAYS_PER_YEAR)


def metres(length):
    """A length (length units) in metres (a length unit is 0.3 m).

    >>> metres(0.2)
    0.06
    """
    return length * METRES_PER_LENGTH_UNIT


def unwrap(x: np.ndarray, radius: float) -> np.ndarray:
    """``(arc length, height)`` of 3-D points on the trunk, arc length ``r·θ`` in ``[0, 2πr)`` with θ
    increasing to the right as seen from outside the trunk (bark's convention)."""
    theta = np.mod(np.arctan2(x[:, 1], x[:, 0]), 2 * np.pi)
    return np.column_stack([radius * theta, x[:, 2]])
