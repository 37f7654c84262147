"""The sizes kronlag accepts from its inputs, in one place: each input is checked against its limit
before any work, so that a hostile or mistaken input ends in one line rather than a hang, a
traceback or an exhausted memory (docs/model-files.md, docs/cli.md).

The limits of expression texts are those of :mod:`kronlag.model.expressions`."""

from __future__ import annotations

__all__ = ["MAX_MODEL_FILE_BYTES", "MAX_NESTING", "MAX_ENTRIES", "MAX_PARAMETERS", "MAX_OUTPUT_POINTS"]

#: Largest model file (bytes of TOML): at most this much (plus one byte) is read.
MAX_MODEL_FILE_BYTES = 16 * 2**20

#: Deepest nesting of arrays and tables in a model file (the built-in models nest 5 deep).
MAX_NESTING = 32

#: Most entries of one array or table of a model file (bodies, joints, loads, named points, ...),
#: besides ``[parameters]``: deriving the equations of so many bodies would take hours.
MAX_ENTRIES = 1000

#: Most parameters of a model file.
MAX_PARAMETERS = 10_000

#: Most output times of one run (``t_eval``, ``--points``, ``--dt``): a row holds the state, the
#: accelerations and the multipliers, so 10^6 rows of a 10-coordinate model take 0.3 GB.
MAX_OUTPUT_POINTS = 1_000_000
