//! # frictionless-py — the Python extension `frictionless._native`
//!
//! What this crate **is**: the PyO3 (abi3, CPython ≥ 3.9) bindings that the pure-Python package
//! `frictionless` (in `python/frictionless/`) wraps. Each binding calls the one Rust implementation:
//! - [`model`]: `.fwt` models (`frictionless::weights`) — load, inspect, batch inference on NumPy
//!   arrays with the core's kernel (`frictionless::kernel::Mlp`, the GIL released), and writing a
//!   `.fwt` from NumPy weights (PyTorch `nn.Linear` order).
//! - [`estimator`]: the per-joint PINN estimator (`frictionless::model::PinnEstimator`) stepped one
//!   sample at a time with frictiond's semantics (bumpless reset at the first sample after a reset).
//! - [`fit`]: CV / SCV / SCV-code fits on arrays through `frictionless-ident`'s fitter.
//! - [`client`]: a client of a running `frictiond` over iceoryx2 (`frictionless-shm-types`).
//!
//! What it is **not**: no friction model, filter, law or fitter of its own, no file format of its
//! own, no Python-side numerics. The Python API, its docstrings and type stubs are in
//! `python/frictionless/`; the tests are `python/tests/` (pytest, run by `python/ci.sh`).
//!
//! Building: `pip install ./python` (maturin, see `python/pyproject.toml`). Only maturin turns on
//! PyO3's `extension-module` feature (`[tool.maturin] features`: libpython left unlinked, as a wheel
//! needs); `cargo build/test/clippy --workspace` build the crate like any PyO3 embedding (linked
//! against the libpython PyO3 finds) and run no test binary of it.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

pub mod client;
pub mod estimator;
pub mod fit;
pub mod model;

create_exception!(
    _native,
    FrictionlessError,
    PyException,
    "Base class of the errors raised by frictionless (the message is the Rust error's, causes included)."
);
create_exception!(
    _native,
    WeightFileError,
    FrictionlessError,
    "A `.fwt` file (or the model to write) is not acceptable."
);
create_exception!(
    _native,
    ModelError,
    FrictionlessError,
    "A model cannot be used as asked (e.g. its feature spec does not match the network)."
);
create_exception!(
    _native,
    FitError,
    FrictionlessError,
    "A friction-model fit failed (bad data, bounds, or a result outside the parameter domain)."
);
create_exception!(
    _native,
    IpcError,
    FrictionlessError,
    "An iceoryx2 operation of the frictiond client failed."
);

/// The error and its causes on one line (`frictionless::error_line`).
pub(crate) fn message(e: &(dyn std::error::Error + 'static)) -> String {
    frictionless::error_line(e)
}

/// The extension module `frictionless._native`.
#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("FrictionlessError", py.get_type::<FrictionlessError>())?;
    m.add("WeightFileError", py.get_type::<WeightFileError>())?;
    m.add("ModelError", py.get_type::<ModelError>())?;
    m.add("FitError", py.get_type::<FitError>())?;
    m.add("IpcError", py.get_type::<IpcError>())?;
    m.add_class::<model::Model>()?;
    m.add_function(wrap_pyfunction!(model::fwt_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(model::feature_sets, m)?)?;
    m.add_class::<estimator::Estimator>()?;
    m.add_function(wrap_pyfunction!(fit::fit_static, m)?)?;
    m.add_function(wrap_pyfunction!(fit::friction_torque, m)?)?;
    m.add_function(wrap_pyfunction!(fit::lugre_friction_torque, m)?)?;
    m.add_class::<client::DaemonClient>()?;
    m.add_function(wrap_pyfunction!(client::monotonic_ns, m)?)?;
    m.add("MAX_JOINTS", frictionless_shm_types::MAX_JOINTS)?;
    use frictionless_shm_types as abi;
    for (name, bit) in [
        ("FLAG_CURRENT_SATURATED", abi::FLAG_CURRENT_SATURATED),
        ("FLAG_FRICTION_CLIPPED", abi::FLAG_FRICTION_CLIPPED),
        ("FLAG_NON_FINITE", abi::FLAG_NON_FINITE),
        ("FLAG_STALE", abi::FLAG_STALE),
        ("FLAG_DISABLED", abi::FLAG_DISABLED),
        ("FLAG_FAULT", abi::FLAG_FAULT),
        ("FLAG_WARMING_UP", abi::FLAG_WARMING_UP),
        ("FAULT_DRIVE", abi::FAULT_DRIVE),
        ("FAULT_FEEDBACK_STALE", abi::FAULT_FEEDBACK_STALE),
        ("STATUS_SCHED_FIFO", abi::STATUS_SCHED_FIFO),
        ("STATUS_MEMORY_LOCKED", abi::STATUS_MEMORY_LOCKED),
        ("STATUS_CPU_PINNED", abi::STATUS_CPU_PINNED),
        ("STATUS_INPUT_STALE", abi::STATUS_INPUT_STALE),
        ("STATUS_STOPPING", abi::STATUS_STOPPING),
    ] {
        m.add(name, bit)?;
    }
    // MODEL_KIND_<NAME> for every kind of the core's list (`scv-code` → MODEL_KIND_SCV_CODE).
    for kind in frictionless::model::ModelKind::ALL {
        let name = format!(
            "MODEL_KIND_{}",
            kind.name().to_uppercase().replace('-', "_")
        );
        m.add(name.as_str(), kind.code())?;
    }
    m.add(
        "LUGRE_PARAM_NAMES",
        frictionless::lugre::LugreParams::PARAM_NAMES.to_vec(),
    )?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
