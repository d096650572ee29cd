"""Type stubs of the Rust extension ``frictionless._native`` (PyO3). Use the wrappers in
``frictionless`` (documented there); these are the raw bindings they call."""

from os import PathLike
from typing import Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, PathLike[str]]

__version__: str
MAX_JOINTS: int
FLAG_CURRENT_SATURATED: int
FLAG_FRICTION_CLIPPED: int
FLAG_NON_FINITE: int
FLAG_STALE: int
FLAG_DISABLED: int
FLAG_FAULT: int
FLAG_WARMING_UP: int
FAULT_DRIVE: int
FAULT_FEEDBACK_STALE: int
STATUS_SCHED_FIFO: int
STATUS_MEMORY_LOCKED: int
STATUS_CPU_PINNED: int
STATUS_INPUT_STALE: int
STATUS_STOPPING: int
MODEL_KIND_NONE: int
MODEL_KIND_CV: int
MODEL_KIND_SCV: int
MODEL_KIND_SCV_CODE: int
MODEL_KIND_PINN: int

class FrictionlessError(Exception): ...
class WeightFileError(FrictionlessError): ...
class ModelError(FrictionlessError): ...
class FitError(FrictionlessError): ...
class IpcError(FrictionlessError): ...

class Model:
    @staticmethod
    def load(path: _Path) -> Model: ...
    @staticmethod
    def from_bytes(data: bytes) -> Model: ...
    def to_bytes(self) -> bytes: ...
    def save(self, path: _Path) -> None: ...
    @property
    def n_inputs(self) -> int: ...
    @property
    def kernel_path(self) -> str: ...
    def info_dict(self) -> dict: ...
    def weights(
        self,
    ) -> Tuple[
        list[Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]],
        Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]],
    ]: ...
    def predict_f32(self, x: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]: ...
    def predict_f64(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float32]: ...

def feature_sets() -> list[Tuple[str, list[Tuple[str, str]]]]: ...
def fwt_bytes(
    layers: Sequence[Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]],
    norm: Optional[Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]],
    features: str,
    history: int,
    temperature: bool,
    joint: str,
    gear_ratio: float,
    kt_nm_per_a: float,
    dtype: str,
    scv_prior: Optional[Sequence[float]],
    tool_version: str,
    created_unix_s: int,
    val_rmse_nm: float,
    test_rmse_nm: float,
    filtering: str,
) -> bytes: ...

class Estimator:
    def __init__(
        self, model: Model, warmup: str = "hold_zero", delta_theta_offset_motor_rad: Optional[float] = None
    ) -> None: ...
    def push(
        self,
        s_rad: float,
        sdot_rad_s: float,
        theta_motor_rad: float,
        omega_motor_rad_s: float,
        temperature_c: float = ...,
    ) -> float: ...
    def estimate(self) -> float: ...
    def reset(self) -> None: ...
    @property
    def warm(self) -> bool: ...
    @property
    def ready(self) -> bool: ...
    @property
    def n_samples(self) -> int: ...
    @property
    def warmup(self) -> str: ...
    @property
    def delta_theta_offset_motor_rad(self) -> float: ...
    def last_input(self) -> list[float]: ...

def fit_static(
    model: str,
    sdot_rad_s: npt.NDArray[np.float64],
    tau_f_nm: npt.NDArray[np.float64],
    sliding_quadrants: bool,
    v_min_rad_s: float,
    method: str,
    loss: str,
    epochs: int,
    lr: float,
    bounds: dict[str, float],
) -> dict: ...
def friction_torque(
    model: str, params: Sequence[float], sdot_rad_s: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]: ...
def monotonic_ns() -> int: ...

class DaemonClient:
    def __init__(
        self, service_prefix: str = "frictionless", root_path: Optional[_Path] = None, node_name: str = "frictionless-py"
    ) -> None: ...
    @property
    def service_prefix(self) -> str: ...
    def daemon_up(self) -> bool: ...
    def publish_states(
        self,
        n_joints: int,
        s_rad: Optional[Sequence[float]] = None,
        sdot_rad_s: Optional[Sequence[float]] = None,
        theta_motor_rad: Optional[Sequence[float]] = None,
        omega_motor_rad_s: Optional[Sequence[float]] = None,
        current_a: Optional[Sequence[float]] = None,
        tau_meas_nm: Optional[Sequence[float]] = None,
        temperature_c: Optional[Sequence[float]] = None,
        fault_flags: Optional[Sequence[int]] = None,
        seq: Optional[int] = None,
        stamp_ns: Optional[int] = None,
    ) -> Tuple[int, int]: ...
    def publish_request(
        self,
        tau_des_nm: Sequence[float],
        enable_mask: int,
        state_seq: int = 0,
        seq: Optional[int] = None,
        stamp_ns: Optional[int] = None,
    ) -> Tuple[int, int]: ...
    def command(self, timeout_s: float = 0.0) -> Optional[dict]: ...
    def status(self, timeout_s: float = 0.0) -> Optional[dict]: ...
    def control_get(self, joint: str, timeout_s: float = 2.0) -> dict: ...
    def control_set(self, joint: str, key: str, value: str, timeout_s: float = 2.0) -> dict: ...
