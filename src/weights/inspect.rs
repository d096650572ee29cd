//! A diagnostic view of a `.fwt` header (`frictl inspect`), tolerant of a bad CRC, a truncated
//! payload or bad values: those are reported in the view instead of failing.
//!
//! Not a loader: use [`super::from_bytes`] to get a usable model.

use std::fmt;

use crate::features::{Feature, FeatureSpec};
use crate::friction::ScvParams;
use crate::mlp::StorageDtype;

use super::SignalFiltering;
use super::WeightError;
use super::codec;
use super::layout::{self, LayerInfo, Unit};

/// Everything the header says, the derived sizes, and the integrity verdict.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Inspection {
    /// Format major version.
    pub version_major: u16,
    /// Format minor version.
    pub version_minor: u16,
    /// Feature set, history H and temperature flag.
    pub features: FeatureSpec,
    /// The feature of each input block, in order (from `block_features`, or for a 1.0 file from the
    /// set code).
    pub blocks: Vec<Feature>,
    /// Unit of each input block in order, then the temperature unit if present.
    pub input_units: Vec<Unit>,
    /// Unit of the output (joint-side friction torque).
    pub output_unit: Unit,
    /// Number of raw inputs.
    pub n_inputs: usize,
    /// Per-input normalisation mean (empty if the header is incomplete).
    pub norm_mean: Vec<f32>,
    /// Per-input normalisation scale (empty if the header is incomplete).
    pub norm_scale: Vec<f32>,
    /// Layer table.
    pub layers: Vec<LayerInfo>,
    /// Layer sizes including input and output, e.g. `[40, 268, 215, 1]`.
    pub sizes: Vec<usize>,
    /// Storage dtype of the weights.
    pub dtype: StorageDtype,
    /// Joint name.
    pub joint_name: String,
    /// Signed gear ratio as stored (not yet validated).
    pub gear_ratio: f64,
    /// Torque constant \[Nm/A\] as stored.
    pub kt_nm_per_a: f64,
    /// SCV prior (paper form), if present.
    pub scv: Option<ScvParams>,
    /// Dataset SHA-256, lowercase hex.
    pub dataset_sha256: String,
    /// Validation RMSE \[Nm\] (NaN → JSON null: unknown).
    pub val_rmse_nm: f32,
    /// Test RMSE \[Nm\] (NaN → JSON null: unknown).
    pub test_rmse_nm: f32,
    /// Creation time \[s since the Unix epoch\].
    pub created_unix_s: u64,
    /// Tool that wrote the file.
    pub tool_version: String,
    /// Signal filtering used for training.
    pub filtering: SignalFiltering,
    /// Range of the training inputs (format ≥ 1.2), `None` if the file has none.
    pub input_range: Option<super::InputRange>,
    /// Max |Δτ̂_F| \[Nm\] against the f32 original measured by `frictl convert` (format ≥ 1.3), if any.
    pub quant_max_error_nm: Option<f32>,
    /// SHA-256 (lowercase hex) of the teacher `.fwt` of a distilled model (format ≥ 1.5), if any.
    pub teacher_sha256: Option<String>,
    /// Header length in bytes (unpadded).
    pub header_len: u64,
    /// Payload offset in bytes (64-aligned).
    pub payload_offset: u64,
    /// Payload length in bytes.
    pub payload_len: u64,
    /// Stored parameters (weights + biases).
    pub n_params: usize,
    /// Multiply–accumulates per inference.
    pub macs: usize,
    /// Bytes actually present.
    pub file_len: u64,
    /// Bytes the header declares.
    pub expected_file_len: u64,
    /// CRC-32C stored in the header.
    pub crc_stored: u32,
    /// CRC-32C computed over the bytes present.
    pub crc_computed: u32,
    /// Whether they match.
    pub crc_ok: bool,
    /// `None` if [`super::from_bytes`] accepts the file, else its error message.
    pub error: Option<String>,
}

pub(super) fn inspect(bytes: &[u8]) -> Result<Inspection, WeightError> {
    let h = codec::parse_header(bytes)?;
    let n = h.n_inputs;
    let norm_at = layout::FIXED_HEADER_LEN + h.layers.len() * layout::LAYER_ENTRY_LEN;
    let f32s = |at: usize| -> Vec<f32> {
        // parse_header checked that the whole header (with normalisation) is present.
        bytes
            .get(at..at + 4 * n)
            .unwrap_or(&[])
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    let mut sizes = vec![n];
    sizes.extend(h.layers.iter().map(|l| l.n_out));
    let crc_computed = codec::file_crc(bytes);
    Ok(Inspection {
        version_major: layout::VERSION_MAJOR,
        version_minor: h.version_minor,
        features: h.features,
        blocks: h.features.set.blocks().to_vec(),
        input_units: h.input_units,
        output_unit: layout::OUTPUT_UNIT,
        n_inputs: n,
        norm_mean: f32s(norm_at),
        norm_scale: f32s(norm_at + 4 * n),
        n_params: h.layers.iter().map(|l| l.n_in * l.n_out + l.n_out).sum(),
        macs: h.layers.iter().map(|l| l.n_in * l.n_out).sum(),
        layers: h.layers,
        sizes,
        dtype: h.dtype,
        joint_name: h.joint_name,
        gear_ratio: h.gear_ratio,
        kt_nm_per_a: h.kt_nm_per_a,
        scv: h.scv,
        dataset_sha256: h
            .dataset_sha256
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect(),
        val_rmse_nm: h.val_rmse_nm,
        test_rmse_nm: h.test_rmse_nm,
        created_unix_s: h.created_unix_s,
        tool_version: h.tool_version,
        filtering: h.filtering,
        input_range: h.input_range,
        quant_max_error_nm: h.quant_max_error_nm,
        teacher_sha256: h
            .teacher_sha256
            .map(|t| t.iter().map(|b| format!("{b:02x}")).collect()),
        header_len: h.layout.header_len,
        payload_offset: h.layout.payload_offset,
        payload_len: h.layout.payload_len,
        file_len: bytes.len() as u64,
        expected_file_len: h.layout.file_len,
        crc_stored: h.crc_stored,
        crc_computed,
        crc_ok: crc_computed == h.crc_stored,
        error: codec::decode(bytes).err().map(|e| e.to_string()),
    })
}

fn opt_f32(v: f32) -> String {
    if v.is_nan() {
        "unknown".into()
    } else {
        format!("{v:.6}")
    }
}

impl Inspection {
    /// The input blocks with their units and history lengths, the temperature last.
    fn blocks_text(&self) -> String {
        let h = self.features.history;
        let mut blocks: Vec<String> = self
            .blocks
            .iter()
            .zip(&self.input_units)
            .map(|(b, u)| format!("{} [{}] ×{h}", b.name(), u.symbol()))
            .collect();
        if self.features.temperature {
            blocks.push(format!(
                "temperature [{}] ×1",
                layout::TEMPERATURE_UNIT.symbol()
            ));
        }
        blocks.join(", ")
    }

    /// Every input block's range `r` with its unit, the temperature's last.
    fn input_range_text(&self, r: &super::InputRange) -> String {
        let mut parts: Vec<String> = self
            .blocks
            .iter()
            .zip(&r.blocks)
            .zip(&self.input_units)
            .map(|((b, s), u)| format!("{} [{}, {}] {}", b.name(), s[0], s[1], u.symbol()))
            .collect();
        if self.features.temperature {
            parts.push(format!(
                "temperature [{}, {}] {}",
                r.temperature[0],
                r.temperature[1],
                layout::TEMPERATURE_UNIT.symbol()
            ));
        }
        parts.join(", ")
    }
}

impl fmt::Display for Inspection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let units: Vec<&str> = self.input_units.iter().map(|u| u.symbol()).collect();
        let sizes: Vec<String> = self.sizes.iter().map(usize::to_string).collect();
        writeln!(
            f,
            "format         .fwt {}.{}",
            self.version_major, self.version_minor
        )?;
        writeln!(f, "joint          {}", self.joint_name)?;
        writeln!(f, "gear ratio     {} (signed)", self.gear_ratio)?;
        writeln!(f, "kt             {} Nm/A", self.kt_nm_per_a)?;
        writeln!(
            f,
            "features       {}, H = {}, temperature = {}",
            self.features.set, self.features.history, self.features.temperature
        )?;
        writeln!(f, "blocks         {}", self.blocks_text())?;
        writeln!(
            f,
            "input units    [{}] ({} inputs)",
            units.join(", "),
            self.n_inputs
        )?;
        writeln!(f, "output unit    {}", self.output_unit.symbol())?;
        writeln!(f, "network        {} ({:?})", sizes.join(" → "), self.dtype)?;
        if let Some(e) = self.quant_max_error_nm {
            writeln!(
                f,
                "conversion     max |Δτ̂_F| {e:.3e} Nm against the f32 original"
            )?;
        }
        writeln!(f, "params / MACs  {} / {}", self.n_params, self.macs)?;
        match &self.scv {
            Some(s) => writeln!(
                f,
                "scv            kc={} ka={} kv={} ks={} vs={} alpha={}",
                s.kc, s.ka, s.kv, s.ks, s.vs, s.alpha
            )?,
            None => writeln!(f, "scv            none")?,
        }
        writeln!(f, "dataset sha256 {}", self.dataset_sha256)?;
        if let Some(t) = &self.teacher_sha256 {
            writeln!(f, "teacher sha256 {t} (distilled)")?;
        }
        writeln!(
            f,
            "rmse val/test  {} / {} Nm",
            opt_f32(self.val_rmse_nm),
            opt_f32(self.test_rmse_nm)
        )?;
        writeln!(f, "created        {} (unix s)", self.created_unix_s)?;
        writeln!(f, "tool           {}", self.tool_version)?;
        writeln!(f, "filtering      {:?}", self.filtering)?;
        match &self.input_range {
            None => writeln!(f, "input range    none (never out of range)")?,
            Some(r) => writeln!(f, "input range    {}", self.input_range_text(r))?,
        }
        writeln!(
            f,
            "layout         header {} B, payload @{} ({} B), file {} B (present {} B)",
            self.header_len,
            self.payload_offset,
            self.payload_len,
            self.expected_file_len,
            self.file_len
        )?;
        writeln!(
            f,
            "crc32c         stored {:#010x}, computed {:#010x}: {}",
            self.crc_stored,
            self.crc_computed,
            if self.crc_ok { "ok" } else { "MISMATCH" }
        )?;
        match &self.error {
            None => write!(f, "verdict        valid"),
            Some(e) => write!(f, "verdict        INVALID: {e}"),
        }
    }
}
