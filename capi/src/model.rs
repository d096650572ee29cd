//! `.fwt` models: open (path or bytes), describe, batch predict, share between threads.
//!
//! An `fl_model` is the decoded `.fwt` file plus the kernel laid out once; it is never written after
//! creation and is reference-counted (`Arc`): [`fl_model_retain`] adds an owner, [`fl_model_free`]
//! drops one. Estimators copy what they need at creation, so a model may be freed while estimators
//! made from it live on.

use std::ffi::{CString, c_char};
use std::path::Path;
use std::sync::Arc;

use fl_core::features::WarmupPolicy;
use fl_core::kernel::Mlp;
use fl_core::mlp::StorageDtype;
use fl_core::model::PinnEstimator;
use fl_core::weights::{ModelFile, WeightError};

use crate::friction::fl_scv_params;
use crate::{Fail, arg, arg_mut, arg_str, fl_status, guard};

/// Storage precision of a model's weights (`FL_DTYPE_*`).
pub type fl_dtype = u32;
/// IEEE binary32 weights.
pub const FL_DTYPE_F32: fl_dtype = 0;
/// IEEE binary16 weights.
pub const FL_DTYPE_F16: fl_dtype = 1;
/// bfloat16 weights.
pub const FL_DTYPE_BF16: fl_dtype = 2;
/// Symmetric int8 hidden-layer weights with per-output-channel f32 scales (output layer f32).
pub const FL_DTYPE_INT8: fl_dtype = 3;
/// Symmetric 14-bit fixed-point hidden-layer weights in int16 with per-output-channel f32 scales
/// (output layer f32), multiplied with per-call 15-bit activations in exact integer arithmetic.
pub const FL_DTYPE_INT16: fl_dtype = 4;

/// An open `.fwt` model. Opaque; immutable; safe to use from several threads at once.
pub struct fl_model {
    pub(crate) file: ModelFile,
    /// The kernel laid out once; [`fl_model_predict`] works on a copy (the kernel has scratch state).
    mlp: Mlp,
    joint_name: CString,
    feature_set: CString,
    blocks: Vec<(CString, CString)>,
    layer_sizes: Vec<u32>,
}

/// What a model is (filled by [`fl_model_describe`]). The string and array pointers point into the
/// model and stay valid as long as the model handle they came from.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct fl_model_info {
    /// Joint name, e.g. `"l_ankle_roll"` (NUL-terminated UTF-8).
    pub joint_name: *const c_char,
    /// Feature-set name, e.g. `"delta-theta-joint-vel"` (NUL-terminated).
    pub feature_set: *const c_char,
    /// Number of feature blocks (each `history` values long); describe each with
    /// [`fl_model_feature_block`].
    pub n_blocks: u32,
    /// History length H (samples per block).
    pub history: u32,
    /// Whether one motor-temperature value [°C] follows the blocks.
    pub temperature: bool,
    /// Whether a block is Δθ, i.e. the estimator latches a motor-angle offset at reset.
    pub uses_delta_theta: bool,
    /// Length of one input vector: n_blocks·H (+1 with temperature).
    pub n_inputs: u32,
    /// Signed gear ratio r (motor angle = r · joint angle).
    pub gear_ratio: f64,
    /// Torque constant k_t [Nm/A] the training labels were computed with.
    pub kt_nm_per_a: f64,
    /// Storage precision, `FL_DTYPE_*`.
    pub dtype: fl_dtype,
    /// Number of entries of `layer_sizes`: the input width, each hidden width, the output width.
    pub n_layer_sizes: u32,
    /// Layer sizes, e.g. {40, 268, 215, 1}.
    pub layer_sizes: *const u32,
    /// Whether the file carries the SCV prior of its physics loss (then `scv_prior` holds it).
    pub has_scv_prior: bool,
    /// The SCV prior (all zero when `has_scv_prior` is false).
    pub scv_prior: fl_scv_params,
}

/// One feature block (filled by [`fl_model_feature_block`]); the strings are static.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct fl_feature_block {
    /// Signal name, e.g. `"delta-theta"`, `"joint-vel"` (NUL-terminated).
    pub name: *const c_char,
    /// Unit of the values, e.g. `"motor rad"`, `"rad/s"` (NUL-terminated).
    pub unit: *const c_char,
}

fn cstring(s: &str) -> CString {
    // Names in a `.fwt` are NUL-padded, so an interior NUL cannot occur; cut there if it ever did.
    let cut = s.split('\0').next().unwrap_or("");
    CString::new(cut).unwrap_or_default()
}

fn weight_fail(e: &WeightError) -> Fail {
    let status = match e.kind() {
        WeightError::Io { .. } => fl_status::Io,
        WeightError::NotRegularFile { .. } => fl_status::NotRegularFile,
        _ => fl_status::Format,
    };
    Fail::owned(status, fl_core::error_line(e))
}

impl fl_model {
    fn new(file: ModelFile) -> Result<Self, Fail> {
        // Building an estimator checks everything an estimator needs (spec vs network width).
        PinnEstimator::from_model_file(&file, WarmupPolicy::ZeroPad)
            .map_err(|e| Fail::owned(fl_status::Model, fl_core::error_line(&e)))?;
        let mlp = Mlp::new(&file.mlp, file.dtype)
            .map_err(|e| Fail::owned(fl_status::Model, fl_core::error_line(&e)))?;
        let spec = file.meta.features;
        let blocks = spec
            .set
            .blocks()
            .iter()
            .map(|b| (cstring(b.name()), cstring(b.unit())))
            .collect();
        let layer_sizes = file.mlp.sizes().iter().map(|&n| n as u32).collect();
        Ok(fl_model {
            joint_name: cstring(&file.meta.joint_name),
            feature_set: cstring(spec.set.name()),
            blocks,
            layer_sizes,
            mlp,
            file,
        })
    }

    fn into_handle(self, out: &mut *mut fl_model) {
        *out = Arc::into_raw(Arc::new(self)) as *mut fl_model;
    }

    /// Number of inputs of one vector.
    pub(crate) fn n_inputs(&self) -> usize {
        self.file.meta.features.n_inputs()
    }
}

/// Opens the `.fwt` file at `path` (NUL-terminated UTF-8) and stores a new handle in `*out`.
///
/// Only a regular file is read (a FIFO, a device or a directory is `FL_STATUS_NOT_REGULAR_FILE`,
/// without blocking), and at most the largest valid `.fwt` size. Missing or unreadable:
/// `FL_STATUS_IO`; not a valid `.fwt`: `FL_STATUS_FORMAT`; valid but unusable: `FL_STATUS_MODEL`.
/// Allocates; not for a real-time thread. Free the handle with [`fl_model_free`].
///
/// # Safety
/// `path` is NULL or a NUL-terminated string; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_open(path: *const c_char, out: *mut *mut fl_model) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_model_open: `out` is NULL") }?;
        // SAFETY: caller contract.
        let path = unsafe {
            arg_str(
                path,
                "fl_model_open: `path` is NULL",
                "fl_model_open: `path` is not valid UTF-8",
            )
        }?;
        let file = fl_core::weights::read_file(Path::new(path)).map_err(|e| weight_fail(&e))?;
        fl_model::new(file)
            .map_err(|f| match f.message {
                crate::Message::Owned(m) => Fail::owned(f.status, format!("{path}: {m}")),
                other => Fail {
                    status: f.status,
                    message: other,
                },
            })?
            .into_handle(out);
        Ok(())
    })
}

/// Decodes a `.fwt` image of `len` bytes at `data` and stores a new handle in `*out` (the bytes are
/// not kept). Errors as [`fl_model_open`] (without the file ones). Allocates.
///
/// # Safety
/// `data` is NULL or points to `len` readable bytes; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_from_bytes(
    data: *const u8,
    len: usize,
    out: *mut *mut fl_model,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_model_from_bytes: `out` is NULL") }?;
        if data.is_null() {
            return Err(Fail::null("fl_model_from_bytes: `data` is NULL"));
        }
        // SAFETY: non-null, `len` readable bytes per the caller contract.
        let bytes = unsafe { std::slice::from_raw_parts(data, len) };
        let file = fl_core::weights::from_bytes(bytes).map_err(|e| weight_fail(&e))?;
        fl_model::new(file)?.into_handle(out);
        Ok(())
    })
}

/// Adds an owner to `model` (thread-safe): each [`fl_model_retain`] needs one more
/// [`fl_model_free`]. Does nothing for NULL.
///
/// # Safety
/// `model` is NULL or a live handle from this library.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_retain(model: *const fl_model) {
    if !model.is_null() {
        // SAFETY: a live handle is a pointer from `Arc::into_raw` with a positive count.
        unsafe { Arc::increment_strong_count(model) };
    }
}

/// Drops one owner of `model`; the last one frees it. Does nothing for NULL. Thread-safe.
///
/// # Safety
/// `model` is NULL or a live handle; the caller's reference is dead afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_free(model: *mut fl_model) {
    if !model.is_null() {
        // A panic in a destructor must not unwind into C; there is nothing to report it to.
        let _ = std::panic::catch_unwind(|| {
            // SAFETY: a live handle is a pointer from `Arc::into_raw`; we give back one count.
            drop(unsafe { Arc::from_raw(model as *const fl_model) });
        });
    }
}

/// Fills `*out` with what the model is. Allocation-free.
///
/// # Safety
/// `model` is NULL or a live handle; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_describe(
    model: *const fl_model,
    out: *mut fl_model_info,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let m = unsafe { arg(model, "fl_model_describe: `model` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_model_describe: `out` is NULL") }?;
        let meta = &m.file.meta;
        let spec = meta.features;
        let (has_scv_prior, scv_prior) = match meta.scv {
            Some(p) => (true, fl_scv_params::from(p)),
            None => (false, fl_scv_params::default()),
        };
        *out = fl_model_info {
            joint_name: m.joint_name.as_ptr(),
            feature_set: m.feature_set.as_ptr(),
            n_blocks: spec.set.n_blocks() as u32,
            history: spec.history as u32,
            temperature: spec.temperature,
            uses_delta_theta: spec.set.uses_delta_theta(),
            n_inputs: spec.n_inputs() as u32,
            gear_ratio: meta.gear_ratio.get(),
            kt_nm_per_a: meta.kt_nm_per_a,
            dtype: match m.file.dtype {
                StorageDtype::F32 => FL_DTYPE_F32,
                StorageDtype::F16 => FL_DTYPE_F16,
                StorageDtype::Bf16 => FL_DTYPE_BF16,
                StorageDtype::Int8 => FL_DTYPE_INT8,
                StorageDtype::Int16 => FL_DTYPE_INT16,
            },
            n_layer_sizes: m.layer_sizes.len() as u32,
            layer_sizes: m.layer_sizes.as_ptr(),
            has_scv_prior,
            scv_prior,
        };
        Ok(())
    })
}

/// Describes feature block `index` (0-based, input-vector order, `< n_blocks`): its signal name and
/// unit. `FL_STATUS_INVALID_ARGUMENT` past the last block. Allocation-free.
///
/// # Safety
/// `model` is NULL or a live handle; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_feature_block(
    model: *const fl_model,
    index: u32,
    out: *mut fl_feature_block,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let m = unsafe { arg(model, "fl_model_feature_block: `model` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_model_feature_block: `out` is NULL") }?;
        let (name, unit) = m.blocks.get(index as usize).ok_or(Fail::fixed(
            fl_status::InvalidArgument,
            "fl_model_feature_block: `index` is not below the model's n_blocks",
        ))?;
        *out = fl_feature_block {
            name: name.as_ptr(),
            unit: unit.as_ptr(),
        };
        Ok(())
    })
}

/// Batch prediction: `x` holds `n_rows` raw (un-normalised) input vectors row-major, each
/// `n_inputs` floats (must equal the model's); `out` receives `n_rows` outputs τ_F [Nm, joint side].
/// A row with a NaN or infinite value gives NaN. The same kernel as the estimator and `frictl
/// predict`. Thread-safe on a shared model; allocates one kernel copy per call (not for a real-time
/// thread; use an estimator there).
///
/// # Safety
/// `model` is NULL or a live handle; `x` is NULL or points to `n_rows·n_inputs` readable floats;
/// `out` is NULL or points to `n_rows` writable floats. `n_rows = 0` accepts NULL buffers.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_model_predict(
    model: *const fl_model,
    x: *const f32,
    n_rows: usize,
    n_inputs: usize,
    out: *mut f32,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let m = unsafe { arg(model, "fl_model_predict: `model` is NULL") }?;
        if n_inputs != m.n_inputs() {
            return Err(Fail::owned(
                fl_status::InvalidArgument,
                format!(
                    "fl_model_predict: `n_inputs` = {n_inputs}, the model takes {}",
                    m.n_inputs()
                ),
            ));
        }
        if n_rows == 0 {
            return Ok(());
        }
        if x.is_null() {
            return Err(Fail::null("fl_model_predict: `x` is NULL"));
        }
        if out.is_null() {
            return Err(Fail::null("fl_model_predict: `out` is NULL"));
        }
        // A slice may span at most isize::MAX bytes: check the input buffer's size in bytes (the
        // output's, n_rows floats, is no larger since n_inputs ≥ 1).
        let total = n_rows
            .checked_mul(n_inputs)
            .filter(|&n| n <= isize::MAX as usize / size_of::<f32>())
            .ok_or_else(|| {
                Fail::owned(
                    fl_status::InvalidArgument,
                    format!(
                        "fl_model_predict: `n_rows` = {n_rows} · `n_inputs` = {n_inputs} floats exceed the address space"
                    ),
                )
            })?;
        // SAFETY: non-null, sizes per the caller contract.
        let x = unsafe { std::slice::from_raw_parts(x, total) };
        // SAFETY: as above.
        let out = unsafe { std::slice::from_raw_parts_mut(out, n_rows) };
        let mut mlp = m.mlp.clone();
        for (o, row) in out.iter_mut().zip(x.chunks_exact(n_inputs)) {
            *o = mlp.forward(row);
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fl_core::features::{FeatureSet, FeatureSpec};
    use fl_core::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
    use fl_core::units::GearRatio;
    use fl_core::weights::{ModelMeta, TrainingMeta};
    use std::ffi::CStr;
    use std::ptr;

    /// A row count whose input buffer fits `usize` in elements but not the address space in bytes
    /// (n_rows · n_inputs · 4 > isize::MAX) is refused before any buffer is touched.
    #[test]
    fn predict_refuses_a_row_count_whose_bytes_overflow() {
        let spec = FeatureSpec {
            set: FeatureSet::JointVel,
            history: 5,
            temperature: false,
        };
        let mlp = seeded_mlp(
            &RandomMlpSpec {
                sizes: vec![spec.n_inputs(), 4, 1],
                weights: WeightInit::Uniform { amp: 0.5 },
                bias: -0.2..0.2,
                norm: NormInit::Identity,
            },
            3,
        )
        .unwrap();
        let bytes = fl_core::weights::to_bytes(&ModelFile {
            meta: ModelMeta {
                joint_name: "knee".into(),
                gear_ratio: GearRatio::new(100.0).unwrap(),
                kt_nm_per_a: 0.1,
                features: spec,
                scv: None,
                training: TrainingMeta::unknown("capi predict test", 0),
            },
            dtype: StorageDtype::F32,
            mlp,
        })
        .unwrap();
        let n_in = spec.n_inputs();
        let x = vec![0.25f32; 2 * n_in];
        let mut out = [0f32; 2];
        // SAFETY (whole test): pointers to live locals and a handle made and freed here; the huge
        // row counts are refused before the buffers are read.
        unsafe {
            let mut m = ptr::null_mut();
            assert_eq!(
                fl_model_from_bytes(bytes.as_ptr(), bytes.len(), &mut m),
                fl_status::Ok
            );
            for n_rows in [
                usize::MAX / 4 / n_in,
                usize::MAX / n_in,
                isize::MAX as usize / 4 / n_in + 1,
            ] {
                let st = fl_model_predict(m, x.as_ptr(), n_rows, n_in, out.as_mut_ptr());
                assert_eq!(st, fl_status::InvalidArgument, "n_rows = {n_rows}");
                let msg = CStr::from_ptr(crate::fl_last_error()).to_string_lossy();
                assert!(msg.contains("n_rows"), "n_rows = {n_rows}: {msg}");
            }
            // A real batch still predicts.
            assert_eq!(
                fl_model_predict(m, x.as_ptr(), 2, n_in, out.as_mut_ptr()),
                fl_status::Ok
            );
            assert!(out.iter().all(|v| v.is_finite()));
            fl_model_free(m);
        }
    }
}
