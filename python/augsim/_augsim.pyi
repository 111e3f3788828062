"""Type stubs of augsim's native module (documentation: the docstrings and python/README.md)."""

import os
from typing import Any, Optional, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, os.PathLike]

class AugsimError(RuntimeError): ...
class AugsimWarning(UserWarning): ...

class Solution:
    points: npt.NDArray[np.float64]
    displacement: npt.NDArray[np.float64]
    reaction_force: npt.NDArray[np.float64]
    iterations: int
    load_steps: int
    factorizations: int
    residual: float
    max_displacement: float
    ms: float

def solve(scenario: _Path) -> Solution: ...
def predict(model: _Path, input: npt.ArrayLike) -> npt.NDArray[np.float32]: ...
def read_cloud(path: _Path, units: str = "m", file_units: str | None = None) -> npt.NDArray[np.float64]: ...
def dataset_split(
    dataset: _Path, indices: list[int], validation: int, test: int
) -> tuple[str, list[list[int]]]: ...

CANDIDATE_BASE: int

def weights_digest(path: _Path) -> str: ...

class ModelFolderLock:
    def release(self) -> None: ...

def lock_model_folder(out: _Path) -> ModelFolderLock: ...

class Registered:
    targets: npt.NDArray[np.float64]
    displacement: npt.NDArray[np.float64]
    surface_residual: float
    inliers: int
    points: int
    iterations: int
    from_rest: bool
    warnings: list[str]
    plausible: bool
    rigid: Optional[npt.NDArray[np.float64]]
    target_sigma: Optional[npt.NDArray[np.float64]]
    ms: float
    structures: dict[str, npt.NDArray[np.float64]]
    def to_dict(self) -> dict[str, Any]: ...

class Registration:
    method: str
    units: str
    frame: Optional[str]
    points: npt.NDArray[np.float64]
    targets: npt.NDArray[np.float64]
    target_labels: list[str]
    def __init__(
        self,
        *,
        fem: Optional[_Path] = None,
        model: Optional[_Path] = None,
        scenario: Optional[_Path] = None,
        shape_model: Optional[_Path] = None,
        patient: Optional[_Path] = None,
        use_fem: Optional[bool] = None,
        use_hybrid: bool = False,
        targets: Union[_Path, npt.ArrayLike, None] = None,
        units: Optional[str] = None,
        frame: Optional[str] = None,
        iterations: Optional[int] = None,
        rigid: bool = False,
        structures: Union[_Path, list[_Path], None] = None,
        time_budget_ms: Optional[float] = None,
    ) -> None: ...
    def register(self, cloud: npt.ArrayLike, *, out: Optional[_Path] = None) -> Registered: ...
    def reset(self) -> None: ...

class Estimate:
    iteration: int
    mean: list[float]
    std: list[float]
    innovation: Optional[float]
    gated: int

class Assimilation:
    names: list[str]
    mean: list[float]
    std: list[float]
    iteration: int
    scenario_values: list[float]
    observed_points: npt.NDArray[np.float64]
    observations: npt.NDArray[np.float64]
    def __init__(self, scenario: _Path, *, iterations: Optional[int] = None) -> None: ...
    def step(self, observation: npt.ArrayLike) -> Estimate: ...
