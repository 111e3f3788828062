"""augsim from Python: static FEM solves, registration of intraoperative point clouds (FEM,
U-Net or reduced-order model, warm-started between clouds), U-Net predictions and the ROUKF one step at a time.

The computations are augsim's own (the same code as the ``augsim`` command line); arrays are
NumPy float64 unless said otherwise, lengths in metres unless a ``units`` argument says otherwise ("mm", "cm", "um").
augsim's errors are raised as :class:`AugsimError` with augsim's message, its warnings (a result
that may not be believed, a file left out) issued as :class:`AugsimWarning`; arrays of the wrong
shape raise :class:`ValueError`. The API is described in ``python/README.md``.
"""

from importlib import metadata as _metadata

from ._augsim import (
    Assimilation,
    AugsimError,
    AugsimWarning,
    Estimate,
    Registered,
    Registration,
    Solution,
    predict,
    read_cloud,
    solve,
)

try:
    __version__ = _metadata.version("augsim")
except _metadata.PackageNotFoundError:  # run from the source tree, not installed
    __version__ = "unknown"

__all__ = [
    "Assimilation",
    "AugsimError",
    "AugsimWarning",
    "Estimate",
    "Registered",
    "Registration",
    "Solution",
    "predict",
    "read_cloud",
    "solve",
]
