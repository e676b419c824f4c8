"""Where the Model Checking Contest models are: ``tests/data/mcc`` in this repository.

``$PETROBOT_MCC`` may point at another copy (e.g. a newer contest edition with the same layout:
``oracle.tsv`` and one folder per model holding ``model.pnml``). The models' source and licence are
in ``tests/data/mcc/SOURCE.md``.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MCC = Path(os.environ.get("PETROBOT_MCC") or ROOT / "tests" / "data" / "mcc")
"""The folder holding ``oracle.tsv`` and one folder per model."""


def mcc_dir() -> Path:
    """The folder holding ``oracle.tsv`` and one folder per model.

    Raises:
        RuntimeError: the folder has no ``oracle.tsv``.
    """
    if not (MCC / "oracle.tsv").is_file():
        raise RuntimeError(f"the MCC models are missing: no oracle.tsv in {MCC}")
    return MCC
