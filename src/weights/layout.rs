//! Byte layout of the `.fwt` format: constants, field offsets, numeric codes and the size formula.
//!
//! This is the single source of truth the codec uses; `docs/weights-format.md` describes the same
//! table in prose. It holds no I/O and no validation logic beyond code ↔ enum mapping.

use crate::features::{Feature, FeatureSet};
use crate::mlp::{Activation, StorageDtype};

use super::SignalFiltering;

/// Shape of one dense layer as the header's layer table states it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct LayerInfo {
    /// Inputs.
    pub n_in: usize,
    /// Outputs.
    pub n_out: usize,
    /// Activation after the affine map.
    pub activation: Activation,
}

/// The 8 magic bytes every `.fwt` file starts with (`"FWT\0"` + `"\r\n\x1a\n"`, which catches
/// text-mode transfers that rewrite line endings or stop at Ctrl-Z, as PNG's signature does).
pub const MAGIC: [u8; 8] = *b"FWT\0\r\n\x1a\n";
/// Format major version written and understood. Readers refuse any other major.
pub const VERSION_MAJOR: u16 = 1;
/// Format minor version written. Readers accept any minor of their major. Minor 1 names the feature
/// blocks (`block_features`); a minor-0 file has zeros there and its blocks follow from its set code.
/// Minor 2 adds the optional training input range (`range_present`, `input_range`). Minor 3 adds the
/// int8 storage dtype (code 4) and the measured conversion error (`quant_max_error_nm`). Minor 4 adds
/// the int16 storage dtype (code 5). Minor 5 adds the optional teacher record (`teacher_present`, a
/// SHA-256 after the normalisation) of a distilled model.
pub const VERSION_MINOR: u16 = 5;
/// The first minor version whose header holds `block_features`.
pub const MINOR_BLOCK_FEATURES: u16 = 1;
/// The first minor version whose header may hold the training input range.
pub const MINOR_INPUT_RANGE: u16 = 2;
/// The first minor version with the int8 dtype and the `quant_max_error_nm` header field.
pub const MINOR_INT8: u16 = 3;
/// The first minor version with the int16 dtype.
pub const MINOR_INT16: u16 = 4;
/// The first minor version that may hold the teacher record.
pub const MINOR_TEACHER: u16 = 5;
/// Length of the teacher record in bytes (the teacher file's SHA-256), between the normalisation and
/// the payload padding when `teacher_present` is 1.
pub const TEACHER_LEN: usize = 32;
/// Feature-block slots of the input range (no feature set has more blocks); the temperature range
/// follows them.
pub const RANGE_BLOCKS: usize = 3;
/// Length of the fixed header in bytes (the layer table follows it).
pub const FIXED_HEADER_LEN: usize = 320;
/// Length of one layer-table entry in bytes.
pub const LAYER_ENTRY_LEN: usize = 16;
/// Alignment of the payload start in bytes.
pub const PAYLOAD_ALIGN: usize = 64;
/// Upper bound on the size of any valid `.fwt` file [bytes]: the fixed header, the largest layer
/// table and normalisation, the largest network the limits in [`crate::mlp::limits`] allow in f32,
/// plus alignment slack. [`super::read_file`] refuses larger files before reading them.
pub const MAX_FILE_LEN: u64 = {
    use crate::mlp::limits::{MAX_HIDDEN_LAYERS, MAX_INPUTS, MAX_OUTPUTS, MAX_WIDTH};
    let layers = MAX_HIDDEN_LAYERS + 1;
    let header = FIXED_HEADER_LEN + LAYER_ENTRY_LEN * layers + 8 * MAX_INPUTS + TEACHER_LEN;
    let weights = MAX_INPUTS * MAX_WIDTH
        + (MAX_HIDDEN_LAYERS - 1) * MAX_WIDTH * MAX_WIDTH
        + MAX_WIDTH * MAX_OUTPUTS;
    let biases = MAX_HIDDEN_LAYERS * MAX_WIDTH + MAX_OUTPUTS;
    (header + PAYLOAD_ALIGN * (layers + 1) + 4 * (weights + biases)) as u64
};
/// Longest joint name in bytes (UTF-8; the field is 64 bytes, NUL-padded).
pub const JOINT_NAME_MAX: usize = 63;
/// Longest tool-version string in bytes (UTF-8; the field is 32 bytes, NUL-padded).
pub const TOOL_VERSION_MAX: usize = 31;
/// Number of per-block unit slots (and feature-code slots) in the header.
pub const MAX_BLOCKS: usize = 8;

/// Field offsets inside the fixed header (all little-endian).
pub mod off {
    /// `[u8; 8]` magic.
    pub const MAGIC: usize = 0;
    /// `u16` major version.
    pub const VERSION_MAJOR: usize = 8;
    /// `u16` minor version.
    pub const VERSION_MINOR: usize = 10;
    /// `u32` CRC-32C of the whole file with these four bytes taken as zero.
    pub const CRC: usize = 12;
    /// `u32` header length (fixed header + layer table + normalisation), unpadded.
    pub const HEADER_LEN: usize = 16;
    /// `u32` payload offset (header length rounded up to 64).
    pub const PAYLOAD_OFFSET: usize = 20;
    /// `u64` payload length in bytes.
    pub const PAYLOAD_LEN: usize = 24;
    /// `u64` total file length in bytes.
    pub const FILE_LEN: usize = 32;
    /// `u16` feature-set code.
    pub const FEATURE_SET: usize = 40;
    /// `u8` number of feature blocks.
    pub const N_BLOCKS: usize = 42;
    /// `u8` temperature flag (0 or 1).
    pub const TEMPERATURE: usize = 43;
    /// `u32` history length H.
    pub const HISTORY: usize = 44;
    /// `u32` number of network inputs.
    pub const N_INPUTS: usize = 48;
    /// `u8` number of dense layers (hidden + output).
    pub const N_LAYERS: usize = 52;
    /// `u8` storage dtype code.
    pub const DTYPE: usize = 53;
    /// `u8` output unit code.
    pub const OUTPUT_UNIT: usize = 54;
    /// `u8` signal-filtering code.
    pub const FILTERING: usize = 55;
    /// `[u8; 8]` unit code per feature block (unused slots zero).
    pub const BLOCK_UNITS: usize = 56;
    /// `u8` unit code of the temperature input (zero without temperature).
    pub const TEMPERATURE_UNIT: usize = 64;
    /// `u8` SCV presence flag (0 or 1).
    pub const SCV_PRESENT: usize = 65;
    /// `u8` training-input-range presence flag (0 or 1; minor ≥ 2, reserved zero before).
    pub const RANGE_PRESENT: usize = 66;
    /// Reserved, zero: `u8` (minor 3 and 4), `[u8; 5]` up to and including `QUANT_MAX_ERROR` before
    /// minor 3; from minor 5 on this byte is [`TEACHER_PRESENT`].
    pub const RESERVED_A: usize = 67;
    /// `u8` teacher-record presence flag (0 or 1; minor ≥ 5): the header then ends with the
    /// [`super::TEACHER_LEN`]-byte SHA-256 of the teacher `.fwt` after the normalisation.
    pub const TEACHER_PRESENT: usize = 67;
    /// `f32` max |Δτ̂_F| \[Nm\] of this reduced-precision file against its f32 original, as measured
    /// by `frictl convert` (minor ≥ 3; NaN = not measured; reserved zero before).
    pub const QUANT_MAX_ERROR: usize = 68;
    /// `f64` signed gear ratio.
    pub const GEAR_RATIO: usize = 72;
    /// `f64` torque constant \[Nm/A\].
    pub const KT: usize = 80;
    /// `[f64; 6]` SCV kc, ka, kv, ks, vs, alpha (zero when absent).
    pub const SCV: usize = 88;
    /// `[u8; 32]` dataset SHA-256.
    pub const DATASET_SHA256: usize = 136;
    /// `f32` validation RMSE \[Nm\].
    pub const VAL_RMSE: usize = 168;
    /// `f32` test RMSE \[Nm\].
    pub const TEST_RMSE: usize = 172;
    /// `u64` creation time \[s since the Unix epoch\].
    pub const CREATED: usize = 176;
    /// `[u8; 64]` joint name, UTF-8, NUL-padded.
    pub const JOINT_NAME: usize = 184;
    /// `[u8; 32]` tool version, UTF-8, NUL-padded.
    pub const TOOL_VERSION: usize = 248;
    /// `[u8; 8]` feature code of each block in order, unused slots zero (minor ≥ 1; zero in 1.0).
    pub const BLOCK_FEATURES: usize = 280;
    /// `[f32; 8]` training input range (minor ≥ 2): `min, max` of feature blocks 0, 1, 2, then of the
    /// temperature; unused slots and an absent range zero.
    pub const INPUT_RANGE: usize = 288;
}

/// Physical unit codes used for the inputs and the output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Unit {
    /// Joint-side angle \[rad\] (code 1).
    JointRad,
    /// Joint-side velocity \[rad/s\] (code 2).
    JointRadS,
    /// Motor-side angle \[motor rad\] (code 3).
    MotorRad,
    /// Motor-side velocity \[motor rad/s\] (code 4).
    MotorRadS,
    /// Temperature \[°C\] (code 5).
    Celsius,
    /// Joint-side torque \[Nm\] (code 6).
    JointNm,
}

impl Unit {
    /// The stable numeric code.
    pub fn code(self) -> u8 {
        match self {
            Unit::JointRad => 1,
            Unit::JointRadS => 2,
            Unit::MotorRad => 3,
            Unit::MotorRadS => 4,
            Unit::Celsius => 5,
            Unit::JointNm => 6,
        }
    }
    /// The unit for a code, if known.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Unit::JointRad,
            2 => Unit::JointRadS,
            3 => Unit::MotorRad,
            4 => Unit::MotorRadS,
            5 => Unit::Celsius,
            6 => Unit::JointNm,
            _ => return None,
        })
    }
    /// Short symbol, e.g. "motor rad/s".
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::JointRad => "rad",
            Unit::JointRadS => "rad/s",
            Unit::MotorRad => "motor rad",
            Unit::MotorRadS => "motor rad/s",
            Unit::Celsius => "°C",
            Unit::JointNm => "Nm",
        }
    }
}

/// Stable code of a feature set. Codes 1–4 equal the authors' `input_type`; 5 is reserved for their
/// input type 5; 6 is the June 2024 `[s, θ]` model; 7 and 8 need no motor encoder.
pub fn feature_set_code(set: FeatureSet) -> u16 {
    match set {
        FeatureSet::DeltaThetaJointVel => 1,
        FeatureSet::MotorVelJointVel => 2,
        FeatureSet::DeltaThetaMotorVelJointVel => 3,
        FeatureSet::DeltaThetaJointPosJointVel => 4,
        FeatureSet::JointPosMotorPos => 6,
        FeatureSet::JointPosJointVel => 7,
        FeatureSet::JointVel => 8,
    }
}

/// Feature set for a code, if known.
pub fn feature_set_from_code(code: u16) -> Option<FeatureSet> {
    FeatureSet::ALL
        .into_iter()
        .find(|&s| feature_set_code(s) == code)
}

/// Stable code of one feature block (`block_features`; 0 marks an unused slot).
pub fn feature_code(f: Feature) -> u8 {
    match f {
        Feature::DeltaThetaMotorRad => 1,
        Feature::JointVelRadS => 2,
        Feature::MotorVelRadS => 3,
        Feature::JointPosRad => 4,
        Feature::MotorPosRad => 5,
    }
}

/// Feature for a block code, if known.
pub fn feature_from_code(code: u8) -> Option<Feature> {
    Feature::ALL.into_iter().find(|&f| feature_code(f) == code)
}

/// The unit of a feature block's values.
pub fn feature_unit(f: Feature) -> Unit {
    match f {
        Feature::DeltaThetaMotorRad | Feature::MotorPosRad => Unit::MotorRad,
        Feature::JointVelRadS => Unit::JointRadS,
        Feature::MotorVelRadS => Unit::MotorRadS,
        Feature::JointPosRad => Unit::JointRad,
    }
}

/// Units of the blocks of a feature set, in block order.
pub fn block_units(set: FeatureSet) -> Vec<Unit> {
    set.blocks().iter().map(|&f| feature_unit(f)).collect()
}

/// The unit of the network output: joint-side friction torque.
pub const OUTPUT_UNIT: Unit = Unit::JointNm;
/// The unit of the optional temperature input.
pub const TEMPERATURE_UNIT: Unit = Unit::Celsius;

/// Stable code of a storage dtype.
pub fn dtype_code(d: StorageDtype) -> u8 {
    match d {
        StorageDtype::F32 => 1,
        StorageDtype::F16 => 2,
        StorageDtype::Bf16 => 3,
        StorageDtype::Int8 => 4,
        StorageDtype::Int16 => 5,
    }
}

/// Storage dtype for a code, if known.
pub fn dtype_from_code(code: u8) -> Option<StorageDtype> {
    Some(match code {
        1 => StorageDtype::F32,
        2 => StorageDtype::F16,
        3 => StorageDtype::Bf16,
        4 => StorageDtype::Int8,
        5 => StorageDtype::Int16,
        _ => return None,
    })
}

/// Stable code of an activation.
pub fn activation_code(a: Activation) -> u8 {
    match a {
        Activation::Relu => 1,
        Activation::Identity => 2,
    }
}

/// Activation for a code, if known.
pub fn activation_from_code(code: u8) -> Option<Activation> {
    Some(match code {
        1 => Activation::Relu,
        2 => Activation::Identity,
        _ => return None,
    })
}

/// Stable code of a signal-filtering kind.
pub fn filtering_code(f: SignalFiltering) -> u8 {
    match f {
        SignalFiltering::Unknown => 0,
        SignalFiltering::Causal => 1,
        SignalFiltering::NonCausal => 2,
    }
}

/// Signal filtering for a code, if known.
pub fn filtering_from_code(code: u8) -> Option<SignalFiltering> {
    Some(match code {
        0 => SignalFiltering::Unknown,
        1 => SignalFiltering::Causal,
        2 => SignalFiltering::NonCausal,
        _ => return None,
    })
}

/// Sizes of the parts of a file, all in bytes, as the spec's formula gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Layout {
    /// Fixed header + layer table + normalisation (+ teacher record, minor ≥ 5), unpadded.
    pub header_len: u64,
    /// `header_len` rounded up to a multiple of 64.
    pub payload_offset: u64,
    /// Weights and biases of every layer in the storage dtype.
    pub payload_len: u64,
    /// `payload_offset + payload_len`: the whole file.
    pub file_len: u64,
}

impl Layout {
    /// The layout for `n_inputs` raw inputs, `n_layers` layers holding `n_params` weights + biases,
    /// stored with `dtype_size` bytes per value. Arithmetic is in u64; callers pass sizes already
    /// checked against [`crate::mlp::limits`], for which it cannot overflow.
    pub fn new(n_inputs: u64, n_layers: u64, n_params: u64, dtype_size: u64) -> Self {
        let header_len = FIXED_HEADER_LEN as u64 + LAYER_ENTRY_LEN as u64 * n_layers + 8 * n_inputs;
        let align = PAYLOAD_ALIGN as u64;
        let payload_offset = header_len.div_ceil(align) * align;
        let payload_len = n_params * dtype_size;
        Self {
            header_len,
            payload_offset,
            payload_len,
            file_len: payload_offset + payload_len,
        }
    }

    /// The same layout with `extra` more header bytes (the teacher record): header length, payload
    /// offset and file length move, the payload length stays.
    pub fn with_extra_header(self, extra: u64) -> Self {
        let header_len = self.header_len + extra;
        let align = PAYLOAD_ALIGN as u64;
        let payload_offset = header_len.div_ceil(align) * align;
        Self {
            header_len,
            payload_offset,
            payload_len: self.payload_len,
            file_len: payload_offset + self.payload_len,
        }
    }

    /// The layout for `n_inputs` raw inputs and the dense layers `(n_in, n_out)` (first to last)
    /// stored as `dtype`: [`Layout::new`] for f32/f16/bf16; for int8 (int16) every hidden layer takes
    /// `n_in·n_out` (`2·n_in·n_out`) bytes of codes plus `n_out` f32 scales and `n_out` f32 biases,
    /// the output layer `4·(n_in + n_out)` bytes (f32).
    pub fn for_layers(n_inputs: u64, dtype: StorageDtype, layers: &[(u64, u64)]) -> Self {
        let n_layers = layers.len() as u64;
        if !matches!(dtype, StorageDtype::Int8 | StorageDtype::Int16) {
            let n_params = layers.iter().map(|&(i, o)| (i + 1) * o).sum();
            return Self::new(n_inputs, n_layers, n_params, dtype.size_bytes() as u64);
        }
        let payload_len: u64 = layers
            .iter()
            .enumerate()
            .map(|(k, &(i, o))| {
                if k + 1 == layers.len() {
                    4 * (i * o + o)
                } else {
                    dtype.size_bytes() as u64 * i * o + 8 * o
                }
            })
            .sum();
        let mut l = Self::new(n_inputs, n_layers, 0, 0);
        l.payload_len = payload_len;
        l.file_len = l.payload_offset + payload_len;
        l
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_maps_back_to_its_value_and_unknown_codes_are_none() {
        let mut seen = 0;
        for c in 0..=255u8 {
            if let Some(u) = Unit::from_code(c) {
                assert_eq!(u.code(), c);
                seen += 1;
            }
            if let Some(d) = dtype_from_code(c) {
                assert_eq!(dtype_code(d), c);
            }
            if let Some(a) = activation_from_code(c) {
                assert_eq!(activation_code(a), c);
            }
            if let Some(f) = filtering_from_code(c) {
                assert_eq!(filtering_code(f), c);
            }
        }
        assert_eq!(seen, 6);
        for c in 0..=255u8 {
            if let Some(f) = feature_from_code(c) {
                assert_eq!(feature_code(f), c);
                assert_eq!(feature_unit(f).symbol(), f.unit(), "{f}");
            }
        }
        assert_eq!(feature_from_code(0), None, "0 means an unused slot");
        assert_eq!(Unit::from_code(0), None, "0 means an unused slot");
        let mut sets = 0;
        for c in 0..=u16::MAX {
            if let Some(s) = feature_set_from_code(c) {
                assert_eq!(feature_set_code(s), c);
                assert_eq!(block_units(s).len(), s.n_blocks());
                assert!(s.n_blocks() <= MAX_BLOCKS);
                sets += 1;
            }
        }
        assert_eq!(sets, FeatureSet::ALL.len(), "every set has its own code");
        // The authors' input types keep their numbers; the v1.0 codes are unchanged.
        assert_eq!(feature_set_code(FeatureSet::DeltaThetaJointVel), 1);
        assert_eq!(feature_set_code(FeatureSet::MotorVelJointVel), 2);
        assert_eq!(feature_set_code(FeatureSet::DeltaThetaMotorVelJointVel), 3);
        assert_eq!(feature_set_code(FeatureSet::DeltaThetaJointPosJointVel), 4);
        assert_eq!(feature_set_code(FeatureSet::JointPosMotorPos), 6);
        assert_eq!(feature_set_from_code(5), None, "reserved for input_type 5");
    }

    #[test]
    fn field_offsets_tile_the_fixed_header() {
        // (offset, size) of every fixed-header field in order: no gaps, no overlaps, 320 bytes.
        let fields = [
            (off::MAGIC, 8),
            (off::VERSION_MAJOR, 2),
            (off::VERSION_MINOR, 2),
            (off::CRC, 4),
            (off::HEADER_LEN, 4),
            (off::PAYLOAD_OFFSET, 4),
            (off::PAYLOAD_LEN, 8),
            (off::FILE_LEN, 8),
            (off::FEATURE_SET, 2),
            (off::N_BLOCKS, 1),
            (off::TEMPERATURE, 1),
            (off::HISTORY, 4),
            (off::N_INPUTS, 4),
            (off::N_LAYERS, 1),
            (off::DTYPE, 1),
            (off::OUTPUT_UNIT, 1),
            (off::FILTERING, 1),
            (off::BLOCK_UNITS, MAX_BLOCKS),
            (off::TEMPERATURE_UNIT, 1),
            (off::SCV_PRESENT, 1),
            (off::RANGE_PRESENT, 1),
            (off::RESERVED_A, 1),
            (off::QUANT_MAX_ERROR, 4),
            (off::GEAR_RATIO, 8),
            (off::KT, 8),
            (off::SCV, 48),
            (off::DATASET_SHA256, 32),
            (off::VAL_RMSE, 4),
            (off::TEST_RMSE, 4),
            (off::CREATED, 8),
            (off::JOINT_NAME, JOINT_NAME_MAX + 1),
            (off::TOOL_VERSION, TOOL_VERSION_MAX + 1),
            (off::BLOCK_FEATURES, MAX_BLOCKS),
            (off::INPUT_RANGE, 4 * 2 * (RANGE_BLOCKS + 1)),
        ];
        let mut at = 0;
        for (o, size) in fields {
            assert_eq!(o, at, "field at {o}");
            // Naturally aligned multi-byte scalars.
            if matches!(size, 2 | 4 | 8) {
                assert_eq!(o % size, 0, "field at {o} misaligned");
            }
            at += size;
        }
        assert_eq!(at, FIXED_HEADER_LEN);
    }

    #[test]
    fn layout_of_the_ergocub_network() {
        let l = Layout::new(40, 3, 69_039, 4);
        assert_eq!((l.header_len, l.payload_offset), (688, 704));
        assert_eq!(l.file_len, 704 + 4 * 69_039);
    }
}
