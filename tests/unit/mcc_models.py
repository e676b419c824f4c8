"""Where the Model Checking Contest models are: ``$PETROBOT_MCC``, else ``shared/mcc`` beside the
project (as on the developers' and CI machines), else ``/work/shared/mcc``.

Under CI (``CI`` set) missing models are an error, not a reason to skip the tests that need them.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_CANDIDATES = [os.environ.get("PETROBOT_MCC") or "", str(ROOT.parent / "shared" / "mcc"), "/work/shared/mcc"]


def mcc_dir() -> Path:
    """The folder holding ``oracle.tsv`` and one folder per model.

    Raises:
        RuntimeError: under CI, when no candidate holds the models.
    """
    for candidate in _CANDIDATES:
        if candidate and (Path(candidate) / "oracle.tsv").is_file():
            return Path(candidate)
    if os.environ.get("CI"):
        raise RuntimeError(f"the MCC models are missing (looked in {[c for c in _CANDIDATES if c]}); "
                           "set PETROBOT_MCC to the folder holding oracle.tsv")
    return Path(_CANDIDATES[1])


MCC = mcc_dir()
