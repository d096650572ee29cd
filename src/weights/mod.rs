//! The `.fwt` weight file: fixed-size, versioned, self-describing, CRC-32C protected.
//!
//! What this module **is**: the in-memory model description ([`ModelFile`]), the byte codec
//! ([`to_bytes`], [`from_bytes`]), atomic file helpers ([`read_file`], [`write_file`]) and a
//! diagnostic header view ([`inspect`]). The byte-level specification is `docs/weights-format.md`;
//! the offsets and codes live in [`layout`].
//!
//! What it is **not**: no inference (see [`crate::kernel`]), no ONNX/safetensors import or export
//! (that is `frictl`), no memory mapping. The reader checks length, magic, version, sizes, CRC,
//! shape limits and values before it allocates anything sized by the file, and never panics.

mod codec;
mod inspect;
pub mod layout;

use std::io;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::features::FeatureSpec;
use crate::friction::ScvParams;
use crate::mlp::{MlpShapeError, MlpWeights, StorageDtype};
use crate::units::GearRatio;

pub use codec::{encoded_layout, round_to_dtype};
pub use inspect::Inspection;
pub use layout::{LayerInfo, Layout, RANGE_BLOCKS, Unit};

/// Which velocity/current signals the model was trained on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalFiltering {
    /// Not recorded (e.g. imported from ONNX).
    Unknown,
    /// Causal (forward-only) filters, as the daemon sees at run time.
    Causal,
    /// Zero-phase / smoothed (non-causal) filters, as the authors trained.
    NonCausal,
}

/// Provenance and quality of a trained model.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingMeta {
    /// SHA-256 of the training dataset (all zeros if unknown).
    pub dataset_sha256: [u8; 32],
    /// Validation RMSE \[Nm\] (NaN if unknown).
    pub val_rmse_nm: f32,
    /// Test RMSE \[Nm\] (NaN if unknown).
    pub test_rmse_nm: f32,
    /// Creation time, seconds since the Unix epoch.
    pub created_unix_s: u64,
    /// Tool and version that wrote the file, e.g. "frictl 0.1.0" (≤ 31 bytes).
    pub tool_version: String,
    /// Signals the model was trained on.
    pub filtering: SignalFiltering,
    /// Range of the training inputs (training rows only, not validation or test); `None` if unknown
    /// (an imported network, a file before format 1.2): then no input is ever out of range.
    pub input_range: Option<InputRange>,
    /// Max |Δτ̂_F| \[Nm\] of this (reduced-precision) model against its f32 original as measured by
    /// the conversion accuracy gate (`frictl convert`); `None` if not measured (f32 models, files
    /// before format 1.3). Stored as NaN when `None`; when present finite and ≥ 0.
    pub quant_max_error_nm: Option<f32>,
    /// SHA-256 of the teacher `.fwt` file this model was distilled from (`frictl distill`); `None`
    /// for a model trained on labels only, and in files before format 1.5.
    pub teacher_sha256: Option<[u8; 32]>,
}

/// The range `[min, max]` the training rows covered, per feature block (the H samples of one signal
/// share one range) and for the temperature, each in its input's unit. Unused slots are `[0, 0]`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InputRange {
    /// `[min, max]` of feature block `b` (input order) in the block's unit; slots at or beyond the
    /// feature set's block count are `[0, 0]`.
    pub blocks: [[f32; 2]; layout::RANGE_BLOCKS],
    /// `[min, max]` of the motor temperature \[°C\]; `[0, 0]` for a model without temperature.
    pub temperature: [f32; 2],
}

impl InputRange {
    /// The range of the network input rows `rows` (each `spec.n_inputs()` long, laid out as
    /// [`crate::features`] builds them: block `b` at `b·H .. (b+1)·H`, temperature last). `None` if
    /// there are no rows, a row has the wrong length, or a value is not finite.
    pub fn from_rows<'a>(
        spec: &FeatureSpec,
        rows: impl IntoIterator<Item = &'a [f32]>,
    ) -> Option<InputRange> {
        let n_blocks = spec.set.n_blocks().min(layout::RANGE_BLOCKS);
        let h = spec.history;
        let mut lo = [f32::INFINITY; layout::RANGE_BLOCKS + 1];
        let mut hi = [f32::NEG_INFINITY; layout::RANGE_BLOCKS + 1];
        let mut any = false;
        for row in rows {
            if row.len() != spec.n_inputs() {
                return None;
            }
            for b in 0..n_blocks {
                for &v in &row[b * h..(b + 1) * h] {
                    lo[b] = lo[b].min(v);
                    hi[b] = hi[b].max(v);
                }
            }
            if spec.temperature {
                let v = row[n_blocks * h];
                lo[layout::RANGE_BLOCKS] = lo[layout::RANGE_BLOCKS].min(v);
                hi[layout::RANGE_BLOCKS] = hi[layout::RANGE_BLOCKS].max(v);
            }
            any = true;
        }
        if !any {
            return None;
        }
        let mut r = InputRange {
            blocks: [[0.0; 2]; layout::RANGE_BLOCKS],
            temperature: [0.0; 2],
        };
        for b in 0..n_blocks {
            r.blocks[b] = [lo[b], hi[b]];
        }
        if spec.temperature {
            r.temperature = [lo[layout::RANGE_BLOCKS], hi[layout::RANGE_BLOCKS]];
        }
        let finite = r
            .blocks
            .iter()
            .chain(std::iter::once(&r.temperature))
            .all(|s| s[0].is_finite() && s[1].is_finite());
        finite.then_some(r)
    }

    /// Whether `value` lies in `range` widened on each side by `margin` times its width
    /// (`margin` = 0.1 accepts 10 % beyond either end). Allocation-free; NaN is out of range.
    pub fn within(range: [f32; 2], value: f32, margin: f32) -> bool {
        let pad = margin * (range[1] - range[0]);
        value >= range[0] - pad && value <= range[1] + pad
    }
}

impl TrainingMeta {
    /// Provenance unknown (an imported network, a test or bench net): no dataset hash, no RMSEs,
    /// unknown filtering; `tool_version` and `created_unix_s` say who wrote the file and when.
    pub fn unknown(tool_version: impl Into<String>, created_unix_s: u64) -> Self {
        Self {
            dataset_sha256: [0; 32],
            val_rmse_nm: f32::NAN,
            test_rmse_nm: f32::NAN,
            created_unix_s,
            tool_version: tool_version.into(),
            filtering: SignalFiltering::Unknown,
            input_range: None,
            quant_max_error_nm: None,
            teacher_sha256: None,
        }
    }
}

/// Everything about a model besides its weights.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelMeta {
    /// Joint name, e.g. "l_ankle_roll" (≤ 63 bytes UTF-8).
    pub joint_name: String,
    /// Signed gear ratio used for Δθ and the current.
    pub gear_ratio: GearRatio,
    /// Torque constant \[Nm/A\] the labels were computed with.
    pub kt_nm_per_a: f64,
    /// Input features, their order and history.
    pub features: FeatureSpec,
    /// The SCV prior used in the physics loss, if any.
    pub scv: Option<ScvParams>,
    /// Provenance.
    pub training: TrainingMeta,
}

/// A complete model file in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    /// Metadata.
    pub meta: ModelMeta,
    /// Storage precision of the weights.
    pub dtype: StorageDtype,
    /// The network (values already rounded to `dtype` when read from a file).
    pub mlp: MlpWeights,
}

/// Why a `.fwt` file (or a [`ModelFile`] to be written) is not acceptable.
#[derive(Debug, Error)]
pub enum WeightError {
    /// Fewer bytes than the fixed header or the header's own length needs.
    #[error("truncated .fwt data: need at least {expected} bytes, got {got}")]
    Truncated {
        /// Bytes needed.
        expected: u64,
        /// Bytes present.
        got: u64,
    },
    /// The first 8 bytes are not the `.fwt` magic.
    #[error("bad magic {found:02x?}: not a .fwt weight file")]
    BadMagic {
        /// The first (up to) 8 bytes found, zero-filled.
        found: [u8; 8],
    },
    /// The major version is not one this reader understands.
    #[error(
        "unsupported .fwt format version {major}.{minor}; this reader understands major version {supported}"
    )]
    UnsupportedVersion {
        /// Major version in the file.
        major: u16,
        /// Minor version in the file.
        minor: u16,
        /// The major version this reader understands.
        supported: u16,
    },
    /// The CRC-32C over the file does not match the stored one.
    #[error(
        "CRC-32C mismatch: header key `crc32c` = {stored:#010x}, computed {computed:#010x} (file corrupted)"
    )]
    Crc {
        /// CRC stored in the header.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// The network shape is over the limits or inconsistent.
    #[error("network shape: {0}")]
    Shape(#[from] MlpShapeError),
    /// A value that must be finite is NaN or infinite (or overflows the storage dtype).
    #[error("{field}[{index}] = {value} is not finite (as stored)")]
    NonFinite {
        /// Which field or buffer, e.g. "layer 1 weight" or "kt_nm_per_a".
        field: String,
        /// Flat index (0 for scalars).
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// The header's `file_len` says more bytes than present.
    #[error("header key `file_len` = {claimed} bytes, but only {present} bytes are present")]
    HeaderSaysMore {
        /// Bytes the header claims.
        claimed: u64,
        /// Bytes present.
        present: u64,
    },
    /// More bytes are present than the header's `file_len` declares.
    #[error(
        "header key `file_len` = {declared} bytes, but {present} bytes are present (trailing data)"
    )]
    TrailingData {
        /// Bytes the header declares.
        declared: u64,
        /// Bytes present.
        present: u64,
    },
    /// A header key disagrees with the value the rest of the header implies.
    #[error(
        "header key `{field}` = {stored} disagrees with {expected} implied by the rest of the header"
    )]
    Inconsistent {
        /// The header key.
        field: &'static str,
        /// Value stored (or given).
        stored: u64,
        /// Value implied.
        expected: u64,
    },
    /// A text field is not valid NUL-padded UTF-8.
    #[error("header key `{field}` is not valid NUL-padded UTF-8")]
    BadUtf8 {
        /// The header key.
        field: &'static str,
    },
    /// A numeric code is not defined by this format version.
    #[error("header key `{field}` has unknown code {value}")]
    UnknownCode {
        /// The header key.
        field: &'static str,
        /// The code found.
        value: u64,
    },
    /// A value is well-formed but out of its allowed range (e.g. a name too long, kt ≤ 0).
    #[error("`{field}` = {value}: {reason}")]
    Invalid {
        /// Which key.
        field: &'static str,
        /// The value, formatted.
        value: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// A reserved or padding byte is not zero in a file of a minor version this reader knows.
    #[error("byte at offset {offset} (reserved/padding) is {value:#04x}, must be zero")]
    NonZeroReserved {
        /// Byte offset in the file.
        offset: u64,
        /// The byte found.
        value: u8,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
    /// The path is not a regular file (a FIFO, a device, a directory, a socket): refused before it is
    /// opened for reading, so a FIFO cannot block and `/dev/zero` cannot grow memory.
    #[error("{path}: not a regular file ({file_type}); a .fwt model must be a regular file")]
    NotRegularFile {
        /// The file.
        path: PathBuf,
        /// What it is instead, e.g. "FIFO", "character device", "directory".
        file_type: &'static str,
    },
    /// The file is larger than any valid `.fwt` can be ([`layout::MAX_FILE_LEN`]).
    #[error("file is {len} bytes, more than the largest valid .fwt ({max} bytes)")]
    TooLarge {
        /// Bytes in the file.
        len: u64,
        /// [`layout::MAX_FILE_LEN`].
        max: u64,
    },
    /// The network's output is not finite on a representative input (see [`probe_output`]): the
    /// model would command NaN friction on every tick.
    #[error(
        "model output is {value} (not finite) for the probe input {input}; the weights or the normalisation are unusable"
    )]
    NonFiniteOutput {
        /// Which probe input, e.g. "x = +scale".
        input: &'static str,
        /// The output.
        value: f32,
    },
    /// A format error in a named file (from [`read_file`] / [`write_file`]).
    #[error("{path}: {source}")]
    InFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        #[source]
        source: Box<WeightError>,
    },
}

impl WeightError {
    /// The underlying error, with any [`WeightError::InFile`] wrapper removed.
    pub fn kind(&self) -> &WeightError {
        match self {
            WeightError::InFile { source, .. } => source.kind(),
            other => other,
        }
    }
}

/// Serialises a model into `.fwt` bytes.
///
/// Validates everything [`from_bytes`] would check (shapes, limits, finite values, names, codes,
/// feature/input consistency) and rounds weights and biases to `file.dtype` (round-to-nearest-even
/// via `half`); a value that overflows the dtype is an error. Normalisation stays f32.
pub fn to_bytes(file: &ModelFile) -> Result<Vec<u8>, WeightError> {
    codec::encode(file)
}

/// Parses and fully validates `.fwt` bytes; weights are decoded to f32.
///
/// Never panics, and allocates only after the header's sizes are checked against
/// [`crate::mlp::limits`] and against the number of bytes present.
pub fn from_bytes(bytes: &[u8]) -> Result<ModelFile, WeightError> {
    codec::decode(bytes)
}

/// Runs `file`'s network through the inference kernel on representative inputs — all zeros, the
/// normalisation mean, +scale and −scale — and fails if any output is not finite. A tiny
/// normalisation scale or an overflowing weight passes every per-value check yet makes the model
/// output NaN or ±inf on every input; [`to_bytes`] and [`from_bytes`] run this probe.
pub fn probe_output(file: &ModelFile) -> Result<(), WeightError> {
    codec::probe_output(file)
}

/// Reads and validates a `.fwt` file. Every error names `path`.
///
/// Only regular files are read: the path's type is checked before it is opened (a FIFO, a device
/// such as `/dev/zero` or a directory is [`WeightError::NotRegularFile`]), the open uses
/// `O_NONBLOCK` (a FIFO swapped in between check and open cannot block it), the open file's type
/// and size are checked again, a file over [`layout::MAX_FILE_LEN`] is [`WeightError::TooLarge`],
/// and the read is bounded by that size. Only then are the bytes decoded.
pub fn read_file(path: &Path) -> Result<ModelFile, WeightError> {
    let bytes = read_regular_bounded(path)?;
    from_bytes(&bytes).map_err(|e| WeightError::InFile {
        path: path.to_owned(),
        source: Box::new(e),
    })
}

/// The bytes of the regular file `path`, at most [`layout::MAX_FILE_LEN`] of them, undecoded: the
/// same refusals as [`read_file`] (no FIFO, device or directory; bounded size), for callers that look
/// at a possibly broken file ([`inspect`]).
pub fn read_regular_bounded(path: &Path) -> Result<Vec<u8>, WeightError> {
    use crate::regular_file::{self, Refused};
    regular_file::read(path, layout::MAX_FILE_LEN).map_err(|e| match Refused::of(&e) {
        Some(&Refused::NotRegular { file_type }) => WeightError::NotRegularFile {
            path: path.to_owned(),
            file_type,
        },
        Some(&Refused::TooLarge { len, max }) => WeightError::InFile {
            path: path.to_owned(),
            source: Box::new(WeightError::TooLarge { len, max }),
        },
        None => WeightError::Io {
            path: path.to_owned(),
            source: e,
        },
    })
}

/// Writes a `.fwt` file through [`crate::output_file`]: a temporary file in the same directory is
/// written, synced and renamed over `path`, so readers see either the old or the new file, never a
/// partial one; a device, FIFO, directory or symlink at `path` is refused. Every error names `path`
/// (the temporary file is an implementation detail the caller never chose).
pub fn write_file(path: &Path, file: &ModelFile) -> Result<(), WeightError> {
    let bytes = to_bytes(file).map_err(|e| WeightError::InFile {
        path: path.to_owned(),
        source: Box::new(e),
    })?;
    crate::output_file::write(path, &bytes).map_err(|source| WeightError::Io {
        path: path.to_owned(),
        source,
    })
}

/// A header view for diagnostics (`frictl inspect`): works even when the CRC is wrong, the payload
/// is truncated or values are not finite (see [`Inspection::error`]). Fails only when the header
/// itself cannot be decoded (bad magic/version, truncated header, unknown codes, sizes over limits).
pub fn inspect(bytes: &[u8]) -> Result<Inspection, WeightError> {
    inspect::inspect(bytes)
}
