//! `.fwt` models from Python: [`Model`] (load, inspect, batch inference) and [`fwt_bytes`] (a `.fwt`
//! from NumPy weights).
//!
//! What it is: thin bindings over `frictionless::weights` (the codec, the atomic writer) and
//! `frictionless::kernel::Mlp` (the inference kernel frictiond runs). What it is not: a second codec
//! or kernel; names of feature sets, dtypes and filtering come from the core's own `name()`s.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use frictionless::features::{FeatureSet, FeatureSpec};
use frictionless::friction::{ScvParams, StaticFriction};
use frictionless::kernel::Mlp;
use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, StorageDtype};
use frictionless::units::GearRatio;
use frictionless::weights::{self, ModelFile, ModelMeta, SignalFiltering, TrainingMeta};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use crate::{ModelError, WeightFileError, message};

/// The storage dtype's name (`"f32"`, `"f16"`, `"bf16"`, `"int16"`, `"int8"`).
pub(crate) fn dtype_name(d: StorageDtype) -> &'static str {
    d.name()
}

fn parse_dtype(s: &str) -> PyResult<StorageDtype> {
    match s.to_ascii_lowercase().as_str() {
        "f32" | "float32" => Ok(StorageDtype::F32),
        "f16" | "float16" => Ok(StorageDtype::F16),
        "bf16" | "bfloat16" => Ok(StorageDtype::Bf16),
        "int8" => Ok(StorageDtype::Int8),
        "int16" => Ok(StorageDtype::Int16),
        _ => Err(PyValueError::new_err(format!(
            "dtype `{s}`: expected \"f32\", \"f16\", \"bf16\", \"int16\" or \"int8\""
        ))),
    }
}

fn filtering_name(f: SignalFiltering) -> &'static str {
    match f {
        SignalFiltering::Unknown => "unknown",
        SignalFiltering::Causal => "causal",
        SignalFiltering::NonCausal => "non_causal",
    }
}

fn parse_filtering(s: &str) -> PyResult<SignalFiltering> {
    match s {
        "unknown" => Ok(SignalFiltering::Unknown),
        "causal" => Ok(SignalFiltering::Causal),
        "non_causal" => Ok(SignalFiltering::NonCausal),
        _ => Err(PyValueError::new_err(format!(
            "filtering `{s}`: expected \"unknown\", \"causal\" or \"non_causal\""
        ))),
    }
}

/// The feature set named `name` (its `FeatureSet::name()`, e.g. `"delta-theta-joint-vel"`).
pub(crate) fn parse_feature_set(name: &str) -> PyResult<FeatureSet> {
    FeatureSet::ALL
        .iter()
        .copied()
        .find(|s| s.name() == name)
        .ok_or_else(|| {
            let known: Vec<&str> = FeatureSet::ALL.iter().map(|s| s.name()).collect();
            PyValueError::new_err(format!(
                "feature set `{name}`: expected one of {}",
                known.join(", ")
            ))
        })
}

fn weight_err(e: weights::WeightError) -> PyErr {
    WeightFileError::new_err(message(&e))
}

/// A `.fwt` friction network: metadata plus the kernel that runs it.
///
/// Immutable from Python; [`Model::predict_f32`] / [`Model::predict_f64`] release the GIL while the
/// kernel runs (calls on the same model from several threads take turns on its scratch buffers).
#[pyclass(frozen, module = "frictionless._native")]
pub struct Model {
    file: Arc<ModelFile>,
    mlp: Mutex<Mlp>,
}

impl Model {
    /// Builds the kernel for `file`.
    pub fn new(file: ModelFile) -> PyResult<Self> {
        let mlp = Mlp::new(&file.mlp, file.dtype).map_err(|e| {
            ModelError::new_err(format!(
                "model for joint `{}`: network: {}",
                file.meta.joint_name,
                message(&e)
            ))
        })?;
        Ok(Self {
            file: Arc::new(file),
            mlp: Mutex::new(mlp),
        })
    }

    /// The decoded file.
    pub fn file(&self) -> &Arc<ModelFile> {
        &self.file
    }

    /// Runs the kernel row by row over `x` (row-major, `n_inputs` per row) without the GIL.
    fn run(&self, py: Python<'_>, x: &[f32], n_rows: usize) -> PyResult<Vec<f32>> {
        let n = self.file.mlp.n_inputs();
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "input row {}, column {}: {} is not finite",
                i / n,
                i % n,
                x[i]
            )));
        }
        Ok(py.detach(|| {
            // A poisoned lock only means a panic elsewhere mid-forward; the kernel's scratch is
            // fully overwritten by every forward, so the state is still usable.
            let mut mlp = self.mlp.lock().unwrap_or_else(|p| p.into_inner());
            let mut y = Vec::with_capacity(n_rows);
            for row in x.chunks_exact(n) {
                y.push(mlp.forward(row));
            }
            y
        }))
    }

    fn check_width(&self, cols: usize) -> PyResult<()> {
        let n = self.file.mlp.n_inputs();
        if cols != n {
            return Err(PyValueError::new_err(format!(
                "input has {cols} columns, the model takes {n} ({})",
                self.file.meta.features
            )));
        }
        Ok(())
    }
}

#[pymethods]
impl Model {
    /// Reads and validates a `.fwt` file.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        Self::new(weights::read_file(&path).map_err(weight_err)?)
    }

    /// Parses and validates `.fwt` bytes.
    #[staticmethod]
    fn from_bytes(data: &[u8]) -> PyResult<Self> {
        Self::new(weights::from_bytes(data).map_err(weight_err)?)
    }

    /// The model as `.fwt` bytes.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let b = weights::to_bytes(&self.file).map_err(weight_err)?;
        Ok(PyBytes::new(py, &b))
    }

    /// Writes the model to `path` atomically (temporary file, sync, rename).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        weights::write_file(&path, &self.file).map_err(weight_err)
    }

    /// Number of raw inputs per row.
    #[getter]
    fn n_inputs(&self) -> usize {
        self.file.mlp.n_inputs()
    }

    /// The inference path the kernel uses on this CPU (`"avx512vnni"`, `"avx512"`, `"avx2fma"`, `"portable"`).
    #[getter]
    fn kernel_path(&self) -> String {
        let m = self.mlp.lock().unwrap_or_else(|p| p.into_inner());
        m.path().name().to_owned()
    }

    /// Metadata as a plain dict (the Python `ModelInfo` is built from it).
    fn info_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = &*self.file;
        let m = &f.meta;
        let d = PyDict::new(py);
        d.set_item("joint", &m.joint_name)?;
        d.set_item("gear_ratio", m.gear_ratio.get())?;
        d.set_item("kt_nm_per_a", m.kt_nm_per_a)?;
        d.set_item("feature_set", m.features.set.name())?;
        let blocks = PyList::empty(py);
        for b in m.features.set.blocks() {
            blocks.append((b.name(), b.unit()))?;
        }
        d.set_item("blocks", blocks)?;
        d.set_item("history", m.features.history)?;
        d.set_item("temperature", m.features.temperature)?;
        d.set_item("n_inputs", f.mlp.n_inputs())?;
        d.set_item("input_labels", m.features.input_labels())?;
        d.set_item("dtype", dtype_name(f.dtype))?;
        d.set_item("layers", f.mlp.sizes())?;
        d.set_item("n_params", f.mlp.n_params())?;
        d.set_item("macs", f.mlp.macs())?;
        match &m.scv {
            Some(p) => {
                let s = PyDict::new(py);
                for (name, v) in ScvParams::PARAM_NAMES.iter().zip(p.params()) {
                    s.set_item(*name, v)?;
                }
                d.set_item("scv_prior", s)?;
            }
            None => d.set_item("scv_prior", py.None())?,
        }
        let t = &m.training;
        d.set_item("val_rmse_nm", t.val_rmse_nm)?;
        d.set_item("test_rmse_nm", t.test_rmse_nm)?;
        d.set_item("created_unix_s", t.created_unix_s)?;
        d.set_item("tool_version", &t.tool_version)?;
        d.set_item("filtering", filtering_name(t.filtering))?;
        let sha: String = t
            .dataset_sha256
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        d.set_item("dataset_sha256", sha)?;
        Ok(d)
    }

    /// The network's parameters: `(layers, (mean, scale))` with `layers = [(W, b), ...]`, `W` of
    /// shape `(n_out, n_in)` (PyTorch `nn.Linear.weight`), all float32, as the kernel computes with
    /// them (already rounded to the storage dtype).
    #[allow(clippy::type_complexity)]
    fn weights<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Vec<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<f32>>)>,
        (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>),
    )> {
        let w = &self.file.mlp;
        let mut layers = Vec::with_capacity(w.layers.len());
        for l in &w.layers {
            let flat = PyArray1::from_slice(py, &l.weight);
            let mat = flat
                .reshape([l.n_out, l.n_in])
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            layers.push((mat, PyArray1::from_slice(py, &l.bias)));
        }
        let norm = (
            PyArray1::from_slice(py, &w.norm.mean),
            PyArray1::from_slice(py, &w.norm.scale),
        );
        Ok((layers, norm))
    }

    /// Friction [Nm] for each row of `x` (shape `(n, n_inputs)`, float32).
    fn predict_f32<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let [rows, cols] = [x.shape()[0], x.shape()[1]];
        self.check_width(cols)?;
        let owned: Vec<f32> = match x.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => x.as_array().iter().copied().collect(),
        };
        let y = self.run(py, &owned, rows)?;
        Ok(PyArray1::from_vec(py, y))
    }

    /// Friction [Nm] for each row of `x` (shape `(n, n_inputs)`, float64, converted to the
    /// network's float32).
    fn predict_f64<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let [rows, cols] = [x.shape()[0], x.shape()[1]];
        self.check_width(cols)?;
        let owned: Vec<f32> = x.as_array().iter().map(|&v| v as f32).collect();
        let y = self.run(py, &owned, rows)?;
        Ok(PyArray1::from_vec(py, y))
    }

    fn __repr__(&self) -> String {
        let m = &self.file.meta;
        format!(
            "Model(joint={:?}, features={}, layers={:?}, dtype={}, gear_ratio={}, kt_nm_per_a={})",
            m.joint_name,
            m.features,
            self.file.mlp.sizes(),
            dtype_name(self.file.dtype),
            m.gear_ratio.get(),
            m.kt_nm_per_a
        )
    }
}

/// `(name, [(block name, unit), ...])` of every feature set the core knows.
#[pyfunction]
pub fn feature_sets() -> Vec<(&'static str, Vec<(&'static str, &'static str)>)> {
    FeatureSet::ALL
        .iter()
        .map(|s| {
            (
                s.name(),
                s.blocks().iter().map(|b| (b.name(), b.unit())).collect(),
            )
        })
        .collect()
}

/// Builds `.fwt` bytes from NumPy weights (hidden layers ReLU, the last layer linear). The Python
/// `frictionless.write_fwt` / `frictionless.fwt_bytes` document the arguments.
#[pyfunction]
#[pyo3(signature = (
    layers, norm, features, history, temperature, joint, gear_ratio, kt_nm_per_a, dtype,
    scv_prior, tool_version, created_unix_s, val_rmse_nm, test_rmse_nm, filtering
))]
#[allow(clippy::too_many_arguments)]
pub fn fwt_bytes<'py>(
    py: Python<'py>,
    layers: Vec<(PyReadonlyArray2<'py, f32>, PyReadonlyArray1<'py, f32>)>,
    norm: Option<(PyReadonlyArray1<'py, f32>, PyReadonlyArray1<'py, f32>)>,
    features: &str,
    history: usize,
    temperature: bool,
    joint: String,
    gear_ratio: f64,
    kt_nm_per_a: f64,
    dtype: &str,
    scv_prior: Option<Vec<f64>>,
    tool_version: String,
    created_unix_s: u64,
    val_rmse_nm: f32,
    test_rmse_nm: f32,
    filtering: &str,
) -> PyResult<Bound<'py, PyBytes>> {
    let n_layers = layers.len();
    let mut dense = Vec::with_capacity(n_layers);
    for (k, (w, b)) in layers.iter().enumerate() {
        let (n_out, n_in) = (w.shape()[0], w.shape()[1]);
        dense.push(DenseLayer {
            n_in,
            n_out,
            weight: w.as_array().iter().copied().collect(),
            bias: b.as_array().iter().copied().collect(),
            activation: if k + 1 == n_layers {
                Activation::Identity
            } else {
                Activation::Relu
            },
        });
    }
    let n_in = dense.first().map_or(0, |l| l.n_in);
    let norm = match norm {
        Some((mean, scale)) => Normalisation {
            mean: mean.as_array().iter().copied().collect(),
            scale: scale.as_array().iter().copied().collect(),
        },
        None => Normalisation::identity(n_in),
    };
    let gear_ratio = GearRatio::new(gear_ratio)
        .map_err(|e| WeightFileError::new_err(format!("gear_ratio: {}", message(&e))))?;
    let scv = scv_prior
        .map(|p| {
            ScvParams::from_params(&p)
                .map_err(|e| WeightFileError::new_err(format!("scv_prior: {}", message(&e))))
        })
        .transpose()?;
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: joint,
            gear_ratio,
            kt_nm_per_a,
            features: FeatureSpec {
                set: parse_feature_set(features)?,
                history,
                temperature,
            },
            scv,
            training: TrainingMeta {
                val_rmse_nm,
                test_rmse_nm,
                filtering: parse_filtering(filtering)?,
                ..TrainingMeta::unknown(tool_version, created_unix_s)
            },
        },
        dtype: parse_dtype(dtype)?,
        mlp: MlpWeights {
            norm,
            layers: dense,
        },
    };
    let bytes = weights::to_bytes(&file).map_err(weight_err)?;
    Ok(PyBytes::new(py, &bytes))
}
