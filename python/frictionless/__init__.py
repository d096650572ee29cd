"""frictionless — friction compensation for harmonic-drive joints, from Python.

What this package is: the Python face of the Rust crates in this repository. Every computation runs
in the Rust extension ``frictionless._native`` (PyO3, abi3), which calls the same code as ``frictl``
and ``frictiond``:

- :class:`Model` — a ``.fwt`` network: ``Model.load(path)``, ``Model.from_bytes(b)``,
  ``model.predict(x)`` on an ``(n, n_inputs)`` array (the inference kernel frictiond runs, with the
  GIL released), ``model.info`` (feature blocks, history H, units, joint, signed gear ratio, k_t,
  dtype, layers).
- :class:`Estimator` — one joint's estimator stepped sample by sample with frictiond's semantics
  (bumpless enable, Δθ latch, warm-up policy).
- :func:`write_fwt` / :func:`fwt_bytes` — a ``.fwt`` from NumPy (or PyTorch) weights, so a network
  trained in Python runs in frictiond without ONNX.
- :func:`fit_cv`, :func:`fit_scv`, :func:`fit_scv_code` — the static friction fits of ``frictl fit`` on
  arrays; :func:`friction_torque` evaluates a fitted model; :func:`lugre_friction_torque` steps a
  LuGre model through a velocity sequence.
- ``MODEL_KIND_*`` — the status codes of the core's model kinds (``MODEL_KIND_LUGRE``, …).
- :class:`DaemonClient` — publish joint states and torque requests to a running ``frictiond`` over
  iceoryx2 shared memory and read its current commands and status.

What it is not: a trainer, a reimplementation of any model in Python, or a real-time loop (each call
crosses the Python interpreter; frictiond is the real-time part).

Conventions (as in the Rust core): joint side SI (s [rad], ṡ [rad/s], torques [Nm]); motor side θ
[motor rad], ω_m [motor rad/s]; the gear ratio r is signed (θ = r·s); friction τ_F is joint side.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from os import PathLike
from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import (
    FLAG_CURRENT_SATURATED,
    FLAG_DISABLED,
    FLAG_FAULT,
    FLAG_FRICTION_CLIPPED,
    FLAG_NON_FINITE,
    FLAG_STALE,
    FLAG_WARMING_UP,
    FAULT_DRIVE,
    FAULT_FEEDBACK_STALE,
    LUGRE_PARAM_NAMES as _LUGRE_PARAM_NAMES,
    MAX_JOINTS,
    STATUS_CPU_PINNED,
    STATUS_INPUT_STALE,
    STATUS_MEMORY_LOCKED,
    STATUS_SCHED_FIFO,
    STATUS_STOPPING,
    FitError,
    FrictionlessError,
    IpcError,
    ModelError,
    WeightFileError,
    monotonic_ns,
)

__version__: str = _native.__version__

__all__ = [
    "Model",
    "ModelInfo",
    "FeatureBlock",
    "Estimator",
    "write_fwt",
    "fwt_bytes",
    "feature_sets",
    "FitResult",
    "fit_cv",
    "fit_scv",
    "fit_scv_code",
    "friction_torque",
    "DaemonClient",
    "JointStates",
    "TorqueRequest",
    "MotorCurrentCommand",
    "DaemonStatus",
    "monotonic_ns",
    "FrictionlessError",
    "WeightFileError",
    "ModelError",
    "FitError",
    "IpcError",
    "MAX_JOINTS",
    "FLAG_CURRENT_SATURATED",
    "FLAG_FRICTION_CLIPPED",
    "FLAG_NON_FINITE",
    "FLAG_STALE",
    "FLAG_DISABLED",
    "FLAG_FAULT",
    "FLAG_WARMING_UP",
    "FAULT_DRIVE",
    "FAULT_FEEDBACK_STALE",
    "STATUS_SCHED_FIFO",
    "STATUS_MEMORY_LOCKED",
    "STATUS_CPU_PINNED",
    "STATUS_INPUT_STALE",
    "STATUS_STOPPING",
    "LUGRE_PARAM_NAMES",
    "lugre_friction_torque",
]

# MODEL_KIND_<NAME>: one per kind of the core's `ModelKind` list (the native module defines them
# from it, e.g. MODEL_KIND_PINN, MODEL_KIND_LUGRE), re-exported here without restating the list.
_MODEL_KINDS = {n: getattr(_native, n) for n in dir(_native) if n.startswith("MODEL_KIND_")}
globals().update(_MODEL_KINDS)
__all__ += sorted(_MODEL_KINDS)

#: LuGre parameter names in the order :func:`lugre_friction_torque` takes a sequence.
LUGRE_PARAM_NAMES: Tuple[str, ...] = tuple(_LUGRE_PARAM_NAMES)

PathType = Union[str, "PathLike[str]"]

# --------------------------------------------------------------------------------------------------
# Models


@dataclass(frozen=True)
class FeatureBlock:
    """One per-tick signal of a feature set: its name (e.g. ``"delta-theta"``) and unit."""

    name: str
    unit: str


@dataclass(frozen=True)
class ModelInfo:
    """Metadata of a ``.fwt`` model.

    The input vector is block-major, oldest → newest: ``x[b*H + j]`` is block ``b`` at tick
    ``t - (H-1) + j`` (``j = H-1`` the newest); with ``temperature`` one motor temperature [°C] of the
    newest sample follows at ``x[len(blocks)*H]``. ``input_labels`` names every input.
    """

    joint: str
    gear_ratio: float
    """Signed gear ratio r (motor angle = r · joint angle)."""
    kt_nm_per_a: float
    feature_set: str
    blocks: Tuple[FeatureBlock, ...]
    history: int
    """History length H (samples per block)."""
    temperature: bool
    n_inputs: int
    input_labels: Tuple[str, ...]
    dtype: str
    """Weight storage: ``"f32"``, ``"f16"``, ``"bf16"``, ``"int16"`` or ``"int8"`` (computation is float32)."""
    layers: Tuple[int, ...]
    """Layer sizes including input and output, e.g. ``(40, 268, 215, 1)``."""
    n_params: int
    macs: int
    scv_prior: Optional[dict]
    """The SCV prior of the physics loss (kc, ka, kv, ks, vs, alpha), if recorded."""
    val_rmse_nm: float
    test_rmse_nm: float
    created_unix_s: int
    tool_version: str
    filtering: str
    dataset_sha256: str


def _as_f32(a: Any) -> np.ndarray:
    """A float32 C-contiguous copy/view of an array-like (PyTorch tensors included)."""
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    return np.ascontiguousarray(np.asarray(a, dtype=np.float32))


class Model:
    """A ``.fwt`` friction network (joint-side friction [Nm] from raw, un-normalised inputs).

    Build with :meth:`load`, :meth:`from_bytes` or :func:`write_fwt`. Errors are
    :class:`WeightFileError` / :class:`ModelError` carrying the Rust message.
    """

    __slots__ = ("_m", "_info")

    def __init__(self, native: "_native.Model") -> None:
        self._m = native
        self._info: Optional[ModelInfo] = None

    @classmethod
    def load(cls, path: PathType) -> "Model":
        """Reads and validates a ``.fwt`` file (size, magic, version, CRC, shapes, values)."""
        return cls(_native.Model.load(path))

    @classmethod
    def from_bytes(cls, data: bytes) -> "Model":
        """Parses and validates ``.fwt`` bytes."""
        return cls(_native.Model.from_bytes(bytes(data)))

    def to_bytes(self) -> bytes:
        """The model as ``.fwt`` bytes."""
        return self._m.to_bytes()

    def save(self, path: PathType) -> None:
        """Writes the model atomically (temporary file, fsync, rename)."""
        self._m.save(path)

    @property
    def info(self) -> ModelInfo:
        """The model's metadata (:class:`ModelInfo`)."""
        if self._info is None:
            d = self._m.info_dict()
            d["blocks"] = tuple(FeatureBlock(n, u) for n, u in d["blocks"])
            d["input_labels"] = tuple(d["input_labels"])
            d["layers"] = tuple(d["layers"])
            self._info = ModelInfo(**d)
        return self._info

    @property
    def n_inputs(self) -> int:
        """Raw inputs per row."""
        return self._m.n_inputs

    @property
    def kernel_path(self) -> str:
        """The inference kernel path on this CPU: ``"avx512vnni"``, ``"avx512"``, ``"avx2fma"`` or ``"portable"``."""
        return self._m.kernel_path

    def predict(self, x: Any) -> np.ndarray:
        """Friction [Nm] for each row of ``x``.

        ``x``: shape ``(n, n_inputs)`` (or ``(n_inputs,)`` for one row), float32 or float64 (other
        dtypes are converted to float64; float64 is rounded to the network's float32). Returns a
        float32 array of shape ``(n,)`` (``(1,)`` for one row): exactly what the kernel computes, as
        ``frictl predict`` prints it. The GIL is released while the kernel runs. A non-finite input
        raises ``ValueError`` naming its row and column.
        """
        a = np.asarray(x)
        if a.ndim == 1:
            a = a.reshape(1, -1)
        if a.ndim != 2:
            raise ValueError(f"expected a 2-D array (n, {self.n_inputs}), got shape {a.shape}")
        if a.dtype == np.float32:
            return self._m.predict_f32(np.ascontiguousarray(a))
        return self._m.predict_f64(np.ascontiguousarray(a, dtype=np.float64))

    __call__ = predict

    def weights(self) -> Tuple[list, Tuple[np.ndarray, np.ndarray]]:
        """``(layers, (mean, scale))``: ``layers = [(W, b), ...]`` with ``W`` of shape
        ``(n_out, n_in)`` (PyTorch ``nn.Linear.weight``), float32, as the kernel computes with them
        (rounded to the storage dtype); ``mean``/``scale`` the input normalisation."""
        return self._m.weights()

    def __repr__(self) -> str:
        return self._m.__repr__()


def feature_sets() -> dict:
    """Every feature set the core knows: ``{name: (FeatureBlock, ...)}`` in input order."""
    return {n: tuple(FeatureBlock(b, u) for b, u in blocks) for n, blocks in _native.feature_sets()}


def fwt_bytes(
    layers: Sequence[Tuple[Any, Any]],
    *,
    norm: Optional[Tuple[Any, Any]] = None,
    features: str = "delta-theta-joint-vel",
    history: Optional[int] = None,
    temperature: bool = False,
    joint: str = "joint",
    gear_ratio: float,
    kt: float,
    dtype: str = "f32",
    scv_prior: Optional[dict] = None,
    val_rmse_nm: float = math.nan,
    test_rmse_nm: float = math.nan,
    filtering: str = "unknown",
    created_unix_s: Optional[int] = None,
    tool_version: Optional[str] = None,
) -> bytes:
    """``.fwt`` bytes of an MLP given as NumPy (or PyTorch) arrays; see :func:`write_fwt`."""
    mats = [(_as_f32(w), _as_f32(b).reshape(-1)) for w, b in layers]
    if not mats:
        raise ValueError("layers is empty")
    n_in = mats[0][0].shape[1] if mats[0][0].ndim == 2 else 0
    if history is None:
        blocks = feature_sets().get(features)
        if blocks is None:
            raise ValueError(f"feature set `{features}`: expected one of {', '.join(feature_sets())}")
        rest = n_in - int(temperature)
        if rest <= 0 or rest % len(blocks) != 0:
            raise ValueError(
                f"{n_in} inputs do not split into {len(blocks)} blocks"
                + (" + temperature" if temperature else "")
                + "; pass history="
            )
        history = rest // len(blocks)
    for k, (w, b) in enumerate(mats):
        if w.ndim != 2:
            raise ValueError(f"layer {k}: W must be 2-D (n_out, n_in), got shape {w.shape}")
    nrm = None
    if norm is not None:
        nrm = (_as_f32(norm[0]).reshape(-1), _as_f32(norm[1]).reshape(-1))
    prior = None
    if scv_prior is not None:
        prior = [float(scv_prior[k]) for k in ("kc", "ka", "kv", "ks", "vs", "alpha")]
    return _native.fwt_bytes(
        mats,
        nrm,
        features,
        int(history),
        bool(temperature),
        joint,
        float(gear_ratio),
        float(kt),
        dtype,
        prior,
        tool_version if tool_version is not None else f"frictionless-py {__version__}",
        int(created_unix_s if created_unix_s is not None else time.time()),
        float(val_rmse_nm),
        float(test_rmse_nm),
        filtering,
    )


def write_fwt(path: PathType, layers: Sequence[Tuple[Any, Any]], **kwargs: Any) -> Model:
    """Writes an MLP trained in Python as a ``.fwt`` file frictiond can load; returns it as a Model.

    ``layers``: ``[(W, b), ...]`` first to last, ``W`` of shape ``(n_out, n_in)`` as PyTorch's
    ``nn.Linear.weight`` (tensors are accepted), hidden layers ReLU, the last one linear with one
    output [Nm]. Keywords:

    - ``norm=(mean, scale)``: per-input ``x_norm = (x - mean) / scale`` (default identity);
    - ``features``: the feature set name (default the paper's ``"delta-theta-joint-vel"``; see
      :func:`feature_sets`), ``history`` H (default: inferred from the input width),
      ``temperature`` (one motor temperature [°C] appended);
    - ``joint`` name, ``gear_ratio`` (signed r, required), ``kt`` [Nm/A] (required);
    - ``dtype``: weight storage ``"f32"``, ``"f16"``, ``"bf16"``, ``"int16"`` or ``"int8"``;
    - ``scv_prior``: dict kc, ka, kv, ks, vs, alpha; ``val_rmse_nm``, ``test_rmse_nm``,
      ``filtering`` (``"unknown"``, ``"causal"``, ``"non_causal"``), ``created_unix_s``,
      ``tool_version`` (provenance).

    The file is validated like any ``.fwt`` (shapes, limits, finite values, an output probe) and
    written atomically.
    """
    model = Model.from_bytes(fwt_bytes(layers, **kwargs))
    model.save(path)
    return model


class Estimator:
    """One joint's PINN friction estimator, stepped one sample per tick like frictiond's joint.

    The first :meth:`push` after construction or :meth:`reset` is an enable edge: the history is
    cleared and Δθ = r·s − (θ − θ_off) is latched to 0 at that sample (unless
    ``delta_theta_offset_motor_rad`` fixes θ_off). ``warmup="hold_zero"`` (frictiond's default) returns
    0 until H samples have arrived; ``"zero_pad"`` infers at once with missing samples read as 0.
    """

    __slots__ = ("_e", "model")

    def __init__(
        self,
        model: Model,
        warmup: str = "hold_zero",
        delta_theta_offset_motor_rad: Optional[float] = None,
    ) -> None:
        self.model = model
        self._e = _native.Estimator(model._m, warmup, delta_theta_offset_motor_rad)

    def push(
        self,
        s: float,
        sdot: float,
        theta: float,
        omega: float,
        temperature: float = math.nan,
    ) -> float:
        """One tick: joint position s [rad], joint velocity ṡ [rad/s], motor position θ [motor rad],
        motor velocity ω_m [motor rad/s], motor temperature [°C] (NaN: no sensor). Returns the
        friction estimate [Nm] for this sample."""
        return self._e.push(s, sdot, theta, omega, temperature)

    def estimate(self) -> float:
        """The friction estimate [Nm] of the newest sample (0 before the first push)."""
        return self._e.estimate()

    def reset(self) -> None:
        """Disable: the next push is an enable edge."""
        self._e.reset()

    @property
    def warm(self) -> bool:
        """Whether H samples arrived since the enable (frictiond's ``FLAG_WARMING_UP`` is clear)."""
        return self._e.warm

    @property
    def ready(self) -> bool:
        """Whether the warm-up policy lets the network run."""
        return self._e.ready

    @property
    def n_samples(self) -> int:
        """Samples held since the enable (≤ H)."""
        return self._e.n_samples

    @property
    def warmup(self) -> str:
        """The warm-up policy."""
        return self._e.warmup

    @property
    def delta_theta_offset_motor_rad(self) -> float:
        """θ_off [motor rad] in use (latched or fixed)."""
        return self._e.delta_theta_offset_motor_rad

    def last_input(self) -> np.ndarray:
        """The network input of the last inference (float32)."""
        return np.asarray(self._e.last_input(), dtype=np.float32)

    def __repr__(self) -> str:
        return self._e.__repr__()


# --------------------------------------------------------------------------------------------------
# Static friction fits


@dataclass(frozen=True)
class FitResult:
    """A static friction fit; ``model``/``params`` are those of ``frictl fit --json``."""

    model: str
    """``"Cv"``, ``"Scv"`` or ``"ScvCode"``."""
    params: dict
    """Parameters by name (CV: kc, ka, kv; SCV: kc, ka, kv, ks, vs, alpha; code form: fc, fs, fv, vs)."""
    method: str
    param_names: Tuple[str, ...]
    rmse_fitted_nm: float
    mae_fitted_nm: float
    n_samples: int
    iterations: int
    bounds: dict
    at_bounds: Tuple[str, ...]
    sliding_quadrants: bool
    v_min_rad_s: float

    def torque(self, sdot: Any) -> np.ndarray:
        """τ_F(ṡ) [Nm] of the fitted model for each velocity [rad/s]."""
        return friction_torque(self.model, self.params, sdot)

    def to_json(self) -> dict:
        """The fit as a JSON-ready dict (``frictl eval``/``train``/frictiond tooling read ``model``
        and ``params``)."""
        d = dataclasses.asdict(self)
        d["param_names"] = list(self.param_names)
        d["at_bounds"] = list(self.at_bounds)
        return d


_NAMES = {
    "cv": ("kc", "ka", "kv"),
    "scv": ("kc", "ka", "kv", "ks", "vs", "alpha"),
    "scv_code": ("fc", "fs", "fv", "vs"),
}
_TAGS = {"Cv": "cv", "Scv": "scv", "ScvCode": "scv_code"}


def _fit(
    model: str,
    sdot: Any,
    tau_f: Any,
    sliding_quadrants: bool,
    v_min_rad_s: float,
    method: str,
    loss: str,
    epochs: int,
    lr: float,
    bounds: dict,
) -> FitResult:
    v = np.ascontiguousarray(np.asarray(sdot, dtype=np.float64).reshape(-1))
    t = np.ascontiguousarray(np.asarray(tau_f, dtype=np.float64).reshape(-1))
    d = _native.fit_static(
        model, v, t, sliding_quadrants, float(v_min_rad_s), method, loss, int(epochs), float(lr),
        {k: float(x) for k, x in bounds.items()},
    )
    d["param_names"] = tuple(d["param_names"])
    d["at_bounds"] = tuple(d["at_bounds"])
    return FitResult(**d)


_FIT_DOC = """

    ``sdot``: joint velocity [rad/s], ``tau_f``: friction label [Nm] (same length). As ``frictl fit``:
    only sliding samples with friction opposing motion are fitted (``|ṡ| > v_min_rad_s`` and
    ``ṡ·τ_F > 0``) unless ``sliding_quadrants=False``; ``method="lm"`` (projected
    Levenberg–Marquardt, default) or ``"adam"`` (the paper's procedure, with ``loss``, ``epochs``,
    ``lr``); keyword bounds ``ka_min``, ``ka_max``, ``vs_min``, ``vs_max``, ``alpha_min``,
    ``alpha_max``, ``ks_max_ratio`` override the defaults. Raises :class:`FitError`.
    """


def fit_cv(sdot: Any, tau_f: Any, *, sliding_quadrants: bool = True, v_min_rad_s: float = 0.03,
           method: str = "lm", loss: str = "l1", epochs: int = 3000, lr: float = 0.01,
           **bounds: float) -> FitResult:
    return _fit("cv", sdot, tau_f, sliding_quadrants, v_min_rad_s, method, loss, epochs, lr, bounds)


def fit_scv(sdot: Any, tau_f: Any, *, sliding_quadrants: bool = True, v_min_rad_s: float = 0.03,
            method: str = "lm", loss: str = "l1", epochs: int = 3000, lr: float = 0.01,
            **bounds: float) -> FitResult:
    return _fit("scv", sdot, tau_f, sliding_quadrants, v_min_rad_s, method, loss, epochs, lr, bounds)


def fit_scv_code(sdot: Any, tau_f: Any, *, sliding_quadrants: bool = True,
                 v_min_rad_s: float = 0.03, method: str = "lm", loss: str = "l1",
                 epochs: int = 3000, lr: float = 0.01, **bounds: float) -> FitResult:
    return _fit("scv_code", sdot, tau_f, sliding_quadrants, v_min_rad_s, method, loss, epochs, lr,
                bounds)


fit_cv.__doc__ = "Fits Coulomb–viscous τ_F = kc·tanh(ka·ṡ) + kv·ṡ." + _FIT_DOC
fit_scv.__doc__ = (
    "Fits Stribeck–Coulomb–viscous (paper form) "
    "τ_F = kv·ṡ + (kc + (ks − kc)·exp(−|ṡ/vs|^α))·tanh(ka·ṡ)." + _FIT_DOC
)
fit_scv_code.__doc__ = "Fits the authors' code form of SCV (sign(ṡ), α = 2): fc, fs, fv, vs." + _FIT_DOC


def friction_torque(model: str, params: Any, sdot: Any) -> np.ndarray:
    """τ_F(ṡ) [Nm] of a static model for each velocity [rad/s].

    ``model``: ``"cv"``, ``"scv"``, ``"scv_code"`` (or the fit JSON tags ``"Cv"``, ``"Scv"``,
    ``"ScvCode"``); ``params``: a dict by name or a sequence in the fit JSON's order.
    """
    key = _TAGS.get(model, model)
    if key not in _NAMES:
        raise ValueError(f"model `{model}`: expected cv, scv or scv_code")
    if isinstance(params, dict):
        params = [float(params[n]) for n in _NAMES[key]]
    v = np.ascontiguousarray(np.asarray(sdot, dtype=np.float64).reshape(-1))
    return _native.friction_torque(key, [float(p) for p in params], v)


def lugre_friction_torque(params: Any, sdot: Any, dt_s: float = 1e-3) -> np.ndarray:
    """τ_F [Nm] of a LuGre model stepped through the velocities ``sdot`` [rad/s], one sample every
    ``dt_s`` [s], from bristle state 0 — what frictiond's LuGre joint outputs after an enable (the
    core's ``LugreEstimator``).

    ``params``: a dict by :data:`LUGRE_PARAM_NAMES` (``kc``, ``kv``, ``ks``, ``vs``, ``alpha``,
    ``sigma0``, ``sigma1``; joint side SI) or a sequence in that order. Raises ``ValueError`` naming
    a bad parameter or step.
    """
    if isinstance(params, dict):
        params = [float(params[n]) for n in LUGRE_PARAM_NAMES]
    v = np.ascontiguousarray(np.asarray(sdot, dtype=np.float64).reshape(-1))
    return _native.lugre_friction_torque([float(p) for p in params], v, float(dt_s))


# --------------------------------------------------------------------------------------------------
# frictiond client


def _arr(n: int, fill: float = 0.0) -> np.ndarray:
    return np.full(n, fill, dtype=np.float64)


@dataclass
class JointStates:
    """Joint and motor state of ``n_joints`` joints (plant → daemon), ``frictionless::JointStates_v1``.

    Arrays have length ``n_joints``; ``tau_meas_nm`` and ``temperature_c`` are NaN when unavailable.
    ``seq``/``stamp_ns`` of ``None`` are filled in by :meth:`DaemonClient.publish_states`.
    """

    n_joints: int
    s_rad: np.ndarray = None  # type: ignore[assignment]
    sdot_rad_s: np.ndarray = None  # type: ignore[assignment]
    theta_motor_rad: np.ndarray = None  # type: ignore[assignment]
    omega_motor_rad_s: np.ndarray = None  # type: ignore[assignment]
    current_a: np.ndarray = None  # type: ignore[assignment]
    tau_meas_nm: np.ndarray = None  # type: ignore[assignment]
    temperature_c: np.ndarray = None  # type: ignore[assignment]
    fault_flags: np.ndarray = None  # type: ignore[assignment]
    seq: Optional[int] = None
    stamp_ns: Optional[int] = None

    def __post_init__(self) -> None:
        n = self.n_joints
        for name in ("s_rad", "sdot_rad_s", "theta_motor_rad", "omega_motor_rad_s", "current_a"):
            if getattr(self, name) is None:
                setattr(self, name, _arr(n))
        for name in ("tau_meas_nm", "temperature_c"):
            if getattr(self, name) is None:
                setattr(self, name, _arr(n, math.nan))
        if self.fault_flags is None:
            self.fault_flags = np.zeros(n, dtype=np.uint32)


@dataclass
class TorqueRequest:
    """Desired joint torques τ_des [Nm] and the enabled joints (controller → daemon),
    ``frictionless::TorqueRequest_v2``. ``state_seq`` is the ``seq`` of the state the request answers
    (a lockstep daemon waits for it; 0 = not tied to a state)."""

    tau_des_nm: np.ndarray
    enable_mask: int
    state_seq: int = 0
    seq: Optional[int] = None
    stamp_ns: Optional[int] = None


@dataclass(frozen=True)
class MotorCurrentCommand:
    """Motor current references (daemon → plant), ``frictionless::MotorCurrentCommand_v2``."""

    seq: int
    stamp_ns: int
    state_stamp_ns: int
    state_seq: int
    """``seq`` of the JointStates this command answers."""
    valid_mask: int
    n_joints: int
    i_ref_a: np.ndarray
    """Current reference [A] per joint (clamped, finite)."""
    flags: np.ndarray
    """Per-joint ``FLAG_*`` bits."""
    tau_f_model_nm: np.ndarray
    """The friction estimate the control law was given [Nm] per joint: the model's output (blended
    to the static model out of range under ``ood = "static"``), before kfc, clip and filter; 0 for a
    joint that did not run its model."""

    def is_valid(self, j: int) -> bool:
        """Whether ``i_ref_a[j]`` is a valid command."""
        return 0 <= j < MAX_JOINTS and bool(self.valid_mask >> j & 1)


@dataclass(frozen=True)
class DaemonStatus:
    """Daemon health snapshot, ``frictionless::DaemonStatus_v2``. Histograms are dicts (counts per
    log2-µs bucket, total, max_ns, mean_ns, p50/p99 bucket upper bounds)."""

    seq: int
    stamp_ns: int
    ticks: int
    missed_deadlines: int
    stale_ticks: int
    generation: int
    input_age_ns: int
    period_ns: int
    flags: int
    n_joints: int
    lateness: dict
    compute: dict
    input_age: dict
    tau_f_hat_nm: np.ndarray
    """τ̂_F [Nm] per joint after clip, kfc and filter."""
    i_ref_a: np.ndarray
    joint_flags: np.ndarray
    model_kind: np.ndarray
    """``MODEL_KIND_*`` per joint."""
    bus: dict
    """The backend's link counters: ``kind`` (``"shm"``, ``"can"``), ``links``, ``rx_messages``,
    ``tx_messages``, ``tx_dropped``, ``error_reports``, ``link_down``, ``io_errors``,
    ``stale_feedback_mask`` and ``detail`` (backend-specific counters by name, e.g. CAN's
    ``error_passive``)."""


def _command(d: Optional[dict]) -> Optional[MotorCurrentCommand]:
    if d is None:
        return None
    d["i_ref_a"] = np.asarray(d["i_ref_a"], dtype=np.float64)
    d["flags"] = np.asarray(d["flags"], dtype=np.uint32)
    d["tau_f_model_nm"] = np.asarray(d["tau_f_model_nm"], dtype=np.float64)
    return MotorCurrentCommand(**d)


def _status(d: Optional[dict]) -> Optional[DaemonStatus]:
    if d is None:
        return None
    d["tau_f_hat_nm"] = np.asarray(d["tau_f_hat_nm"], dtype=np.float64)
    d["i_ref_a"] = np.asarray(d["i_ref_a"], dtype=np.float64)
    d["joint_flags"] = np.asarray(d["joint_flags"], dtype=np.uint32)
    d["model_kind"] = np.asarray(d["model_kind"], dtype=np.uint8)
    return DaemonStatus(**d)


def _list(a: Any) -> list:
    return [float(v) for v in np.asarray(a, dtype=np.float64).reshape(-1)]


class DaemonClient:
    """A seat in a running frictiond's shared-memory services (iceoryx2).

    ``service_prefix`` and ``root_path`` are frictiond's ``[backend] service_prefix`` and
    ``root_path``. The client can act as the plant (:meth:`publish_states`), the controller
    (:meth:`publish_request`) and a monitor (:meth:`command`, :meth:`status`). Publishers are opened
    on first use. The client belongs to the thread that created it; waits hold the GIL.
    """

    def __init__(self, service_prefix: str = "frictionless", root_path: Optional[PathType] = None,
                 node_name: str = "frictionless-py") -> None:
        self._c = _native.DaemonClient(service_prefix, root_path, node_name)

    def wait_for_daemon(self, timeout_s: float = 10.0) -> bool:
        """Waits until frictiond's status publisher is up; returns whether it is."""
        deadline = time.monotonic() + timeout_s
        while not self._c.daemon_up():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def publish_states(self, states: JointStates) -> int:
        """Publishes ``states`` (``seq``/``stamp_ns`` filled in when ``None``); returns its seq."""
        n = states.n_joints
        seq, stamp = self._c.publish_states(
            n,
            _list(states.s_rad),
            _list(states.sdot_rad_s),
            _list(states.theta_motor_rad),
            _list(states.omega_motor_rad_s),
            _list(states.current_a),
            _list(states.tau_meas_nm),
            _list(states.temperature_c),
            [int(v) for v in np.asarray(states.fault_flags).reshape(-1)],
            states.seq,
            states.stamp_ns,
        )
        return seq

    def publish_request(self, request: TorqueRequest) -> int:
        """Publishes ``request`` (``seq``/``stamp_ns`` filled in when ``None``); returns its seq."""
        seq, _ = self._c.publish_request(
            _list(request.tau_des_nm), int(request.enable_mask), int(request.state_seq),
            request.seq, request.stamp_ns,
        )
        return seq

    def command(self, timeout_s: float = 0.0) -> Optional[MotorCurrentCommand]:
        """The newest command, waiting up to ``timeout_s`` for one; ``None`` if none arrived."""
        return _command(self._c.command(timeout_s))

    def command_for(self, state_seq: int, timeout_s: float = 10.0) -> Optional[MotorCurrentCommand]:
        """Waits for the command answering state ``state_seq`` (a newer one also ends the wait)."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            c = self.command(min(max(left, 0.0), 0.005))
            if c is not None and c.state_seq >= state_seq:
                return c
            if left <= 0:
                return None

    def status(self, timeout_s: float = 0.0) -> Optional[DaemonStatus]:
        """The newest status, waiting up to ``timeout_s`` for one; ``None`` if none arrived."""
        return _status(self._c.status(timeout_s))

    def control_get(self, joint: str, timeout_s: float = 2.0) -> dict:
        """A joint's values in the running daemon (``<prefix>/control``): ``kfc``,
        ``max_output_friction``, ``max_curr``, ``compensation`` (bool), ``ood``, ``model`` (the
        active model's name: ``default``, an alternate's name or ``none``) with its ``model_kind``,
        ``model_since_tick`` and the joint's ``models``, the ``generation`` with
        ``generation_since_ns``, and ``set_since_ns`` per key (``None``: the file's value). Raises ``ValueError`` for an unknown joint, :class:`IpcError` without a daemon."""
        return self._c.control_get(joint, timeout_s)

    def control_set(self, joint: str, key: str, value, timeout_s: float = 2.0) -> dict:
        """Sets ``key`` (``kfc``, ``max_output_friction``, ``max_curr``, ``compensation``,
        ``ood``, ``model``) of ``joint`` in the running daemon, checked by its config's rules and applied from
        its next tick until a reload. ``value`` as in the config (``True``/``False`` for
        ``compensation`` become ``on``/``off``). Returns the joint's values; raises ``ValueError``
        with the daemon's message (naming the rule) when refused."""
        if isinstance(value, bool):
            value = "on" if value else "off"
        return self._c.control_set(joint, key, str(value), timeout_s)
