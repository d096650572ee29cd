//! Encoder and validating decoder of the `.fwt` byte format (layout in [`super::layout`]).
//!
//! Not public API by itself: [`super::to_bytes`], [`super::from_bytes`] and [`super::inspect`] are
//! the entry points. Every read goes through bounds-checked helpers; sizes from the file are checked
//! against [`crate::mlp::limits`] and against the bytes present before anything is allocated.

use half::{bf16, f16};

use crate::features::FeatureSpec;
use crate::friction::ScvParams;
use crate::mlp::{
    Activation, DenseLayer, MlpShapeError, MlpWeights, Normalisation, StorageDtype, limits,
};
use crate::units::GearRatio;

use super::layout::{self, LayerInfo, Layout, Unit, off};
use super::{ModelFile, ModelMeta, SignalFiltering, TrainingMeta, WeightError};

// ---------------------------------------------------------------------------------------------
// Little-endian readers over a slice whose length the caller has already checked.

fn rd<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut a = [0u8; N];
    // Callers check `b.len() >= FIXED_HEADER_LEN` (or header_len) first; `get` keeps this panic-free
    // even if that invariant were broken (the value then reads as zeros and fails validation).
    if let Some(s) = b.get(at..at + N) {
        a.copy_from_slice(s);
    }
    a
}
fn rd_u8(b: &[u8], at: usize) -> u8 {
    rd::<1>(b, at)[0]
}
fn rd_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(rd(b, at))
}
fn rd_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(rd(b, at))
}
fn rd_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(rd(b, at))
}
fn rd_f32(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(rd(b, at))
}
fn rd_f64(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(rd(b, at))
}

/// CRC-32C of the whole file with the four CRC bytes taken as zero.
pub(super) fn file_crc(bytes: &[u8]) -> u32 {
    let head = bytes.get(..off::CRC).unwrap_or(bytes);
    let tail = bytes.get(off::CRC + 4..).unwrap_or(&[]);
    let c = crc32c::crc32c(head);
    let c = crc32c::crc32c_append(c, &[0u8; 4]);
    crc32c::crc32c_append(c, tail)
}

/// Checks magic, major version and that the fixed header is present.
pub(super) fn check_prefix(bytes: &[u8]) -> Result<(), WeightError> {
    let n = bytes.len().min(8);
    if bytes[..n] != layout::MAGIC[..n] {
        let mut found = [0u8; 8];
        found[..n].copy_from_slice(&bytes[..n]);
        return Err(WeightError::BadMagic { found });
    }
    if bytes.len() >= off::VERSION_MINOR + 2 {
        let major = rd_u16(bytes, off::VERSION_MAJOR);
        if major != layout::VERSION_MAJOR {
            let minor = rd_u16(bytes, off::VERSION_MINOR);
            return Err(WeightError::UnsupportedVersion {
                major,
                minor,
                supported: layout::VERSION_MAJOR,
            });
        }
    }
    if bytes.len() < layout::FIXED_HEADER_LEN {
        return Err(WeightError::Truncated {
            expected: layout::FIXED_HEADER_LEN as u64,
            got: bytes.len() as u64,
        });
    }
    Ok(())
}

/// The decoded header: everything but the normalisation values and the payload.
#[derive(Clone, Debug)]
pub(super) struct Header {
    pub version_minor: u16,
    pub crc_stored: u32,
    pub layout: Layout,
    pub features: FeatureSpec,
    pub input_units: Vec<Unit>,
    pub n_inputs: usize,
    pub dtype: StorageDtype,
    pub filtering: SignalFiltering,
    pub layers: Vec<LayerInfo>,
    pub gear_ratio: f64,
    pub kt_nm_per_a: f64,
    pub scv: Option<ScvParams>,
    pub dataset_sha256: [u8; 32],
    pub val_rmse_nm: f32,
    pub test_rmse_nm: f32,
    pub created_unix_s: u64,
    pub joint_name: String,
    pub tool_version: String,
    pub input_range: Option<super::InputRange>,
    pub quant_max_error_nm: Option<f32>,
    pub teacher_sha256: Option<[u8; 32]>,
}

fn unknown(field: &'static str, value: impl Into<u64>) -> WeightError {
    WeightError::UnknownCode {
        field,
        value: value.into(),
    }
}

fn inconsistent(field: &'static str, stored: u64, expected: u64) -> Result<(), WeightError> {
    if stored == expected {
        Ok(())
    } else {
        Err(WeightError::Inconsistent {
            field,
            stored,
            expected,
        })
    }
}

fn flag(b: &[u8], at: usize, field: &'static str) -> Result<bool, WeightError> {
    match rd_u8(b, at) {
        0 => Ok(false),
        1 => Ok(true),
        v => Err(unknown(field, v)),
    }
}

fn text<const N: usize>(b: &[u8], at: usize, field: &'static str) -> Result<String, WeightError> {
    let raw: [u8; N] = rd(b, at);
    let len = raw
        .iter()
        .position(|&c| c == 0)
        .ok_or(WeightError::BadUtf8 { field })?;
    if raw[len..].iter().any(|&c| c != 0) {
        return Err(WeightError::BadUtf8 { field });
    }
    std::str::from_utf8(&raw[..len])
        .map(str::to_owned)
        .map_err(|_| WeightError::BadUtf8 { field })
}

fn dim(layer: usize, what: &'static str, value: u64, max: usize) -> Result<usize, WeightError> {
    if value == 0 || value > max as u64 {
        // Saturate for the error value on (hypothetical) 32-bit targets.
        let value = usize::try_from(value).unwrap_or(usize::MAX);
        Err(MlpShapeError::Dimension {
            layer,
            what,
            value,
            max,
        }
        .into())
    } else {
        Ok(value as usize)
    }
}

/// Decodes and cross-checks the header (fixed part and layer table). Requires only the header bytes,
/// not the payload; does not check the CRC, reserved bytes or normalisation values.
pub(super) fn parse_header(b: &[u8]) -> Result<Header, WeightError> {
    check_prefix(b)?;
    let version_minor = rd_u16(b, off::VERSION_MINOR);
    let crc_stored = rd_u32(b, off::CRC);

    let (features, n_inputs) = parse_features(b, version_minor)?;
    let input_units = parse_units(b, &features)?;

    let dtype = parse_dtype(b, version_minor)?;
    let f_code = rd_u8(b, off::FILTERING);
    let filtering =
        layout::filtering_from_code(f_code).ok_or_else(|| unknown("filtering", f_code))?;

    // Before minor 5 this byte is reserved (checked to be zero by `decode`, ignored here).
    let teacher_present =
        version_minor >= layout::MINOR_TEACHER && flag(b, off::TEACHER_PRESENT, "teacher_present")?;
    let extra = if teacher_present {
        layout::TEACHER_LEN as u64
    } else {
        0
    };
    let (layers, _) = parse_layer_table(b, n_inputs, extra)?;
    let dims: Vec<(u64, u64)> = layers
        .iter()
        .map(|l| (l.n_in as u64, l.n_out as u64))
        .collect();
    let layout = Layout::for_layers(n_inputs as u64, dtype, &dims).with_extra_header(extra);
    // parse_layer_table checked that the whole header, teacher record included, is present.
    let teacher_sha256 = teacher_present.then(|| {
        let at = layout.header_len as usize - layout::TEACHER_LEN;
        rd::<32>(b, at)
    });
    inconsistent(
        "payload_offset",
        rd_u32(b, off::PAYLOAD_OFFSET).into(),
        layout.payload_offset,
    )?;
    inconsistent(
        "payload_len",
        rd_u64(b, off::PAYLOAD_LEN),
        layout.payload_len,
    )?;
    inconsistent("file_len", rd_u64(b, off::FILE_LEN), layout.file_len)?;

    let scv = parse_scv(b)?;

    let input_range = parse_input_range(b, version_minor)?;

    let quant_max_error_nm = parse_quant_max_error(b, version_minor)?;

    Ok(Header {
        input_range,
        quant_max_error_nm,
        teacher_sha256,
        version_minor,
        crc_stored,
        layout,
        features,
        input_units,
        n_inputs,
        dtype,
        filtering,
        layers,
        gear_ratio: rd_f64(b, off::GEAR_RATIO),
        kt_nm_per_a: rd_f64(b, off::KT),
        scv,
        dataset_sha256: rd(b, off::DATASET_SHA256),
        val_rmse_nm: rd_f32(b, off::VAL_RMSE),
        test_rmse_nm: rd_f32(b, off::TEST_RMSE),
        created_unix_s: rd_u64(b, off::CREATED),
        joint_name: text::<64>(b, off::JOINT_NAME, "joint_name")?,
        tool_version: text::<32>(b, off::TOOL_VERSION, "tool_version")?,
    })
}

/// The storage dtype (int16 only from format 1.4 on).
fn parse_dtype(b: &[u8], version_minor: u16) -> Result<StorageDtype, WeightError> {
    let d_code = rd_u8(b, off::DTYPE);
    let dtype = layout::dtype_from_code(d_code).ok_or_else(|| unknown("dtype", d_code))?;
    if dtype == StorageDtype::Int16 && version_minor < layout::MINOR_INT16 {
        return Err(WeightError::Invalid {
            field: "dtype",
            value: format!("int16 (code {d_code}) in a 1.{version_minor} file"),
            reason: "int16 storage exists from format 1.4 on",
        });
    }
    Ok(dtype)
}

/// The SCV prior, if the file has one.
fn parse_scv(b: &[u8]) -> Result<Option<ScvParams>, WeightError> {
    Ok(if flag(b, off::SCV_PRESENT, "scv_present")? {
        let v = |i: usize| rd_f64(b, off::SCV + 8 * i);
        Some(ScvParams {
            kc: v(0),
            ka: v(1),
            kv: v(2),
            ks: v(3),
            vs: v(4),
            alpha: v(5),
        })
    } else {
        None
    })
}

/// The training rows' input range, if the file has one.
fn parse_input_range(
    b: &[u8],
    version_minor: u16,
) -> Result<Option<super::InputRange>, WeightError> {
    // Before minor 2 these bytes are reserved (checked to be zero by `decode`, ignored here).
    Ok(
        if version_minor >= layout::MINOR_INPUT_RANGE
            && flag(b, off::RANGE_PRESENT, "range_present")?
        {
            let v = |i: usize| rd_f32(b, off::INPUT_RANGE + 4 * i);
            let mut r = super::InputRange {
                blocks: [[0.0; 2]; layout::RANGE_BLOCKS],
                temperature: [v(2 * layout::RANGE_BLOCKS), v(2 * layout::RANGE_BLOCKS + 1)],
            };
            for (k, s) in r.blocks.iter_mut().enumerate() {
                *s = [v(2 * k), v(2 * k + 1)];
            }
            Some(r)
        } else {
            None
        },
    )
}

/// The quantisation's largest error [N·m], if measured (from format 1.3 on).
fn parse_quant_max_error(b: &[u8], version_minor: u16) -> Result<Option<f32>, WeightError> {
    // NaN = not measured; only the canonical quiet NaN the writer uses (so re-encoding reproduces the
    // file); a value is checked (finite, ≥ 0) with the rest of the metadata.
    Ok(if version_minor >= layout::MINOR_INT8 {
        let v = rd_f32(b, off::QUANT_MAX_ERROR);
        if v.is_nan() && v.to_bits() != f32::NAN.to_bits() {
            return Err(WeightError::Invalid {
                field: "quant_max_error_nm",
                value: format!("NaN {:#010x}", v.to_bits()),
                reason: "not measured is the quiet NaN 0x7fc00000",
            });
        }
        Some(v).filter(|v| !v.is_nan())
    } else {
        None
    })
}

/// Reads the feature set, block count, block features (minor ≥ 1), temperature flag and history, and
/// checks the stored input count against them. Returns the feature spec and the input count.
fn parse_features(b: &[u8], version_minor: u16) -> Result<(FeatureSpec, usize), WeightError> {
    let set_code = rd_u16(b, off::FEATURE_SET);
    let set =
        layout::feature_set_from_code(set_code).ok_or_else(|| unknown("feature_set", set_code))?;
    if version_minor >= layout::MINOR_BLOCK_FEATURES {
        // The header names each block; it must be exactly the set's layout, in order.
        let blocks = set.blocks();
        for slot in 0..layout::MAX_BLOCKS {
            let code = rd_u8(b, off::BLOCK_FEATURES + slot);
            let want = blocks.get(slot).map_or(0, |&f| layout::feature_code(f));
            if code != want {
                let field = "block_features";
                return Err(match layout::feature_from_code(code) {
                    None if code != 0 => unknown(field, code),
                    _ => WeightError::Inconsistent {
                        field,
                        stored: code.into(),
                        expected: want.into(),
                    },
                });
            }
        }
    }
    let units = layout::block_units(set);
    inconsistent(
        "n_blocks",
        rd_u8(b, off::N_BLOCKS).into(),
        units.len() as u64,
    )?;
    let temperature = flag(b, off::TEMPERATURE, "temperature")?;
    let history = u64::from(rd_u32(b, off::HISTORY));
    let n_inputs_stored = u64::from(rd_u32(b, off::N_INPUTS));
    let n_inputs = dim(0, "n_in", n_inputs_stored, limits::MAX_INPUTS)?;
    if history == 0 {
        return Err(WeightError::Invalid {
            field: "history",
            value: "0".into(),
            reason: "must be at least 1",
        });
    }
    inconsistent(
        "n_inputs",
        n_inputs_stored,
        units.len() as u64 * history + u64::from(temperature),
    )?;
    let history = history as usize; // ≤ MAX_INPUTS after the check above
    let features = FeatureSpec {
        set,
        history,
        temperature,
    };
    Ok((features, n_inputs))
}

/// Checks the stored unit codes (one per block slot, the temperature unit, the output unit) against
/// the feature set. Returns the units of the input blocks, temperature last if present.
fn parse_units(b: &[u8], features: &FeatureSpec) -> Result<Vec<Unit>, WeightError> {
    let units = layout::block_units(features.set);
    let temperature = features.temperature;
    let mut input_units = Vec::with_capacity(units.len() + 1);
    for slot in 0..layout::MAX_BLOCKS {
        let code = rd_u8(b, off::BLOCK_UNITS + slot);
        let want = units.get(slot).map_or(0, |u| u.code());
        if code != want {
            let field = "block_units";
            return Err(match Unit::from_code(code) {
                None if code != 0 => unknown(field, code),
                _ => WeightError::Inconsistent {
                    field,
                    stored: code.into(),
                    expected: want.into(),
                },
            });
        }
        if let Some(&u) = units.get(slot) {
            input_units.push(u);
        }
    }
    let t_code = rd_u8(b, off::TEMPERATURE_UNIT);
    let t_want = if temperature {
        layout::TEMPERATURE_UNIT.code()
    } else {
        0
    };
    if t_code != t_want {
        if t_code != 0 && Unit::from_code(t_code).is_none() {
            return Err(unknown("temperature_unit", t_code));
        }
        inconsistent("temperature_unit", t_code.into(), t_want.into())?;
    }
    if temperature {
        input_units.push(layout::TEMPERATURE_UNIT);
    }
    let o_code = rd_u8(b, off::OUTPUT_UNIT);
    if Unit::from_code(o_code).is_none() {
        return Err(unknown("output_unit", o_code));
    }
    inconsistent(
        "output_unit",
        o_code.into(),
        layout::OUTPUT_UNIT.code().into(),
    )?;
    Ok(input_units)
}

/// Reads the layer table: the count first (against the depth limit), then the header length and the
/// bytes present, then each entry (width limits, chaining, activations). Nothing is allocated before
/// the count and the bytes are checked. Returns the layers and the parameter count.
fn parse_layer_table(
    b: &[u8],
    n_inputs: usize,
    extra_header: u64,
) -> Result<(Vec<LayerInfo>, u64), WeightError> {
    let n_layers = usize::from(rd_u8(b, off::N_LAYERS));
    if n_layers == 0 {
        return Err(MlpShapeError::Empty.into());
    }
    if n_layers - 1 > limits::MAX_HIDDEN_LAYERS {
        return Err(MlpShapeError::TooDeep(n_layers - 1).into());
    }
    let layout =
        Layout::new(n_inputs as u64, n_layers as u64, 0, 0).with_extra_header(extra_header);
    inconsistent(
        "header_len",
        rd_u32(b, off::HEADER_LEN).into(),
        layout.header_len,
    )?;
    if (b.len() as u64) < layout.header_len {
        return Err(WeightError::Truncated {
            expected: layout.header_len,
            got: b.len() as u64,
        });
    }
    let mut layers = Vec::with_capacity(n_layers);
    let mut n_params = 0u64;
    let mut prev_out = n_inputs;
    for k in 0..n_layers {
        let at = layout::FIXED_HEADER_LEN + k * layout::LAYER_ENTRY_LEN;
        let n_in = u64::from(rd_u32(b, at));
        let max_out = if k + 1 == n_layers {
            limits::MAX_OUTPUTS
        } else {
            limits::MAX_WIDTH
        };
        let n_out = dim(k, "n_out", rd_u32(b, at + 4).into(), max_out)?;
        if n_in != prev_out as u64 {
            let expected = usize::try_from(n_in).unwrap_or(usize::MAX);
            return Err(MlpShapeError::Chain {
                layer: k,
                expected,
                got: prev_out,
            }
            .into());
        }
        let a_code = rd_u8(b, at + 8);
        let activation = layout::activation_from_code(a_code)
            .ok_or_else(|| unknown("layer activation", a_code))?;
        let want = if k + 1 == n_layers {
            Activation::Identity
        } else {
            Activation::Relu
        };
        if activation != want {
            return Err(MlpShapeError::Activation {
                layer: k,
                found: activation,
            }
            .into());
        }
        n_params += (prev_out as u64 + 1) * n_out as u64;
        layers.push(LayerInfo {
            n_in: prev_out,
            n_out,
            activation,
        });
        prev_out = n_out;
    }
    Ok((layers, n_params))
}

/// Byte ranges that must be zero in a file whose minor version this reader knows.
fn reserved_ranges(h: &Header) -> Vec<std::ops::Range<usize>> {
    let mut r = Vec::with_capacity(8 + h.layers.len());
    if h.version_minor < layout::MINOR_INT8 {
        r.push(off::RESERVED_A..off::QUANT_MAX_ERROR + 4);
    } else if h.version_minor < layout::MINOR_TEACHER {
        r.push(off::RESERVED_A..off::QUANT_MAX_ERROR);
    }
    if h.version_minor < layout::MINOR_INPUT_RANGE {
        r.push(off::RANGE_PRESENT..off::RANGE_PRESENT + 1);
        r.push(off::INPUT_RANGE..layout::FIXED_HEADER_LEN);
    } else if h.input_range.is_none() {
        r.push(off::INPUT_RANGE..layout::FIXED_HEADER_LEN);
    }
    if h.version_minor < layout::MINOR_BLOCK_FEATURES {
        r.push(off::BLOCK_FEATURES..off::BLOCK_FEATURES + layout::MAX_BLOCKS);
    }
    if h.scv.is_none() {
        r.push(off::SCV..off::SCV + 48);
    }
    for k in 0..h.layers.len() {
        let at = layout::FIXED_HEADER_LEN + k * layout::LAYER_ENTRY_LEN;
        r.push(at + 9..at + layout::LAYER_ENTRY_LEN);
    }
    r.push(h.layout.header_len as usize..h.layout.payload_offset as usize);
    r
}

fn decode_values(b: &[u8], at: usize, n: usize, dtype: StorageDtype) -> Vec<f32> {
    let s = dtype.size_bytes();
    let bytes = b.get(at..at + n * s).unwrap_or(&[]);
    match dtype {
        StorageDtype::F32 => bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        StorageDtype::F16 => bytes
            .chunks_exact(2)
            .map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        StorageDtype::Bf16 => bytes
            .chunks_exact(2)
            .map(|c| bf16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        StorageDtype::Int8 => bytes.iter().map(|&c| f32::from(c as i8)).collect(),
        StorageDtype::Int16 => bytes
            .chunks_exact(2)
            .map(|c| f32::from(i16::from_le_bytes([c[0], c[1]])))
            .collect(),
    }
}

/// Decodes one int8 or int16 hidden layer at `at`: codes `[n_out][n_in]` (1 or 2 bytes each), scales
/// `[n_out]`, biases `[n_out]`. Returns the dequantised weights, the biases and the bytes consumed. A
/// scale must be finite, ≥ 0 and canonical (what the writer computes for the dequantised row, so
/// re-encoding reproduces the file); a code must lie in the symmetric range (int8 ±127, int16 ±8191)
/// and re-encode to itself at its row's scale.
fn decode_int_layer(
    b: &[u8],
    at: usize,
    n_in: usize,
    n_out: usize,
    layer: usize,
    dtype: StorageDtype,
) -> Result<(Vec<f32>, Vec<f32>, usize), WeightError> {
    /// What differs between the int8 and int16 layers.
    struct IntCodes {
        code_field: &'static str,
        scale_field: &'static str,
        q_max: f32,
        channel_scale: fn(&[f32]) -> f32,
        code_of: fn(f32, f32) -> f32,
    }
    let IntCodes {
        code_field,
        scale_field,
        q_max,
        channel_scale,
        code_of,
    } = if dtype == StorageDtype::Int16 {
        IntCodes {
            code_field: "int16 code",
            scale_field: "int16 scale",
            q_max: f32::from(crate::kernel::I16_WMAX),
            channel_scale: crate::kernel::int16_channel_scale,
            code_of: |w, s| f32::from(crate::kernel::int16_code(w, s)),
        }
    } else {
        IntCodes {
            code_field: "int8 code",
            scale_field: "int8 scale",
            q_max: 127.0,
            channel_scale: crate::kernel::int8_channel_scale,
            code_of: |w, s| f32::from(crate::kernel::int8_code(w, s)),
        }
    };
    let code_bytes = n_in * n_out * dtype.size_bytes();
    let codes = decode_values(b, at, n_in * n_out, dtype);
    let scales = decode_values(b, at + code_bytes, n_out, StorageDtype::F32);
    let bias = decode_values(b, at + code_bytes + 4 * n_out, n_out, StorageDtype::F32);
    finite_all(|| format!("layer {layer} {scale_field}"), &scales)?;
    if let Some(&s) = scales.iter().find(|&&s| s < 0.0) {
        return Err(WeightError::Invalid {
            field: scale_field,
            value: s.to_string(),
            reason: "must be ≥ 0",
        });
    }
    if let Some(&q) = codes.iter().find(|q| q.abs() > q_max) {
        return Err(WeightError::Invalid {
            field: code_field,
            value: format!("{q} (layer {layer})"),
            reason: if dtype == StorageDtype::Int16 {
                "codes are symmetric, −8191 … 8191"
            } else {
                "codes are symmetric, −127 … 127"
            },
        });
    }
    let weight: Vec<f32> = codes
        .chunks(n_in.max(1))
        .zip(&scales)
        .flat_map(|(row, &s)| row.iter().map(move |&q| q * s))
        .collect();
    for ((row, &s), q_row) in weight
        .chunks(n_in.max(1))
        .zip(&scales)
        .zip(codes.chunks(n_in.max(1)))
    {
        // Every code must be what the writer computes for its dequantised weight: a zero scale with
        // non-zero codes, or a scale so small that code·scale rounds, would re-encode differently.
        if let Some(&q) = row
            .iter()
            .zip(q_row)
            .find(|&(&w, &q)| code_of(w, s) != q)
            .map(|(_, q)| q)
        {
            return Err(WeightError::Invalid {
                field: code_field,
                value: format!("{q} (layer {layer}, scale {s:e})"),
                reason: "does not re-encode to itself at its row's scale (a zero or too small scale)",
            });
        }
        let canonical = channel_scale(row);
        if canonical.to_bits() != s.to_bits() {
            return Err(WeightError::Invalid {
                field: scale_field,
                value: s.to_string(),
                reason: "not the canonical scale of its row (max |w| / code range, as the writer computes it)",
            });
        }
    }
    Ok((weight, bias, code_bytes + 8 * n_out))
}

/// Full validating decode (see [`super::from_bytes`]).
pub(super) fn decode(b: &[u8]) -> Result<ModelFile, WeightError> {
    check_prefix(b)?;
    // Order for the most useful diagnosis: when the length matches the header's `file_len`, a CRC
    // mismatch (corruption) is reported before any structural complaint it may have caused; when it
    // does not, the header's structure (limits, codes) is checked first, then the length.
    let declared = rd_u64(b, off::FILE_LEN);
    let present = b.len() as u64;
    if declared == present {
        let computed = file_crc(b);
        let stored = rd_u32(b, off::CRC);
        if computed != stored {
            return Err(WeightError::Crc { stored, computed });
        }
    }
    let h = parse_header(b)?;
    if declared > present {
        return Err(WeightError::HeaderSaysMore {
            claimed: declared,
            present,
        });
    }
    if declared < present {
        return Err(WeightError::TrailingData { declared, present });
    }
    check_reserved(b, &h)?;
    let gear_ratio = GearRatio::new(h.gear_ratio).map_err(|e| WeightError::Invalid {
        field: "gear_ratio",
        value: e.0.to_string(),
        reason: "must be finite and non-zero",
    })?;

    // All sizes below were checked against the limits and the byte count (file_len == len).
    let n = h.n_inputs;
    let norm_at = layout::FIXED_HEADER_LEN + h.layers.len() * layout::LAYER_ENTRY_LEN;
    let norm = Normalisation {
        mean: decode_values(b, norm_at, n, StorageDtype::F32),
        scale: decode_values(b, norm_at + 4 * n, n, StorageDtype::F32),
    };
    let layers = decode_layers(b, &h)?;
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: h.joint_name,
            gear_ratio,
            kt_nm_per_a: h.kt_nm_per_a,
            features: h.features,
            scv: h.scv,
            training: TrainingMeta {
                dataset_sha256: h.dataset_sha256,
                val_rmse_nm: h.val_rmse_nm,
                test_rmse_nm: h.test_rmse_nm,
                created_unix_s: h.created_unix_s,
                tool_version: h.tool_version,
                filtering: h.filtering,
                input_range: h.input_range,
                quant_max_error_nm: h.quant_max_error_nm,
                teacher_sha256: h.teacher_sha256,
            },
        },
        dtype: h.dtype,
        mlp: MlpWeights { norm, layers },
    };
    validate_model(&file)?;
    probe_output(&file)?;
    Ok(file)
}

/// Checks that the reserved bytes of a file of a known minor version are zero.
fn check_reserved(b: &[u8], h: &Header) -> Result<(), WeightError> {
    // `<=` (not `==`): stays right when VERSION_MINOR is raised.
    #[allow(clippy::absurd_extreme_comparisons)]
    let known_minor = h.version_minor <= layout::VERSION_MINOR;
    if known_minor {
        for r in reserved_ranges(h) {
            if let Some((i, &value)) = b
                .get(r.clone())
                .unwrap_or(&[])
                .iter()
                .enumerate()
                .find(|(_, v)| **v != 0)
            {
                return Err(WeightError::NonZeroReserved {
                    offset: (r.start + i) as u64,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// Decodes the payload's layers as the header `h` lays them out (int8/int16: hidden layers as
/// codes + scales + f32 biases, the output layer f32).
fn decode_layers(b: &[u8], h: &Header) -> Result<Vec<DenseLayer>, WeightError> {
    let mut at = h.layout.payload_offset as usize;
    let mut layers = Vec::with_capacity(h.layers.len());
    for (k, l) in h.layers.iter().enumerate() {
        // int8/int16: hidden layers as codes + scales + f32 biases, the output layer f32.
        let dtype = match h.dtype {
            StorageDtype::Int8 | StorageDtype::Int16 if k + 1 == h.layers.len() => {
                StorageDtype::F32
            }
            d => d,
        };
        let (weight, bias) = if matches!(dtype, StorageDtype::Int8 | StorageDtype::Int16) {
            let (w, bias, used) = decode_int_layer(b, at, l.n_in, l.n_out, k, dtype)?;
            at += used;
            (w, bias)
        } else {
            let s = dtype.size_bytes();
            let weight = decode_values(b, at, l.n_in * l.n_out, dtype);
            at += l.n_in * l.n_out * s;
            let bias = decode_values(b, at, l.n_out, dtype);
            at += l.n_out * s;
            (weight, bias)
        };
        layers.push(DenseLayer {
            n_in: l.n_in,
            n_out: l.n_out,
            weight,
            bias,
            activation: l.activation,
        });
    }
    Ok(layers)
}

fn finite_all(field: impl Fn() -> String, v: &[f32]) -> Result<(), WeightError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(WeightError::NonFinite {
            field: field(),
            index,
            value: v[index].into(),
        }),
        None => Ok(()),
    }
}

fn finite(field: &str, value: f64) -> Result<(), WeightError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(WeightError::NonFinite {
            field: field.to_owned(),
            index: 0,
            value,
        })
    }
}

fn text_ok(field: &'static str, s: &str, max: usize) -> Result<(), WeightError> {
    if s.len() > max {
        return Err(WeightError::Invalid {
            field,
            value: format!("{s:?}"),
            reason: "too long for its header field",
        });
    }
    if s.contains('\0') {
        return Err(WeightError::Invalid {
            field,
            value: format!("{s:?}"),
            reason: "must not contain NUL",
        });
    }
    Ok(())
}

/// Rounds one value to the storage dtype (round-to-nearest-even) and back to f32.
fn round_one(v: f32, dtype: StorageDtype) -> f32 {
    match dtype {
        StorageDtype::F32 => v,
        StorageDtype::F16 => f16::from_f32(v).to_f32(),
        StorageDtype::Bf16 => bf16::from_f32(v).to_f32(),
        StorageDtype::Int8 | StorageDtype::Int16 => v, // per channel, see `round_to_dtype`
    }
}

/// A copy of `mlp` with every weight and bias rounded to `dtype` (what [`super::from_bytes`]
/// returns after a [`super::to_bytes`] round trip). The normalisation is not rounded (it is stored
/// as f32); for int8 and int16 only the hidden-layer weights are (per output channel), the rest is
/// f32. Values too large for the dtype become ±∞; [`super::to_bytes`] refuses those.
pub fn round_to_dtype(mlp: &MlpWeights, dtype: StorageDtype) -> MlpWeights {
    if matches!(dtype, StorageDtype::Int8 | StorageDtype::Int16) {
        // Hidden weights quantised per channel; biases and the output layer are stored as f32.
        return crate::kernel::storage_rounded(mlp, dtype);
    }
    let mut out = mlp.clone();
    for l in &mut out.layers {
        for v in l.weight.iter_mut().chain(l.bias.iter_mut()) {
            *v = round_one(*v, dtype);
        }
    }
    out
}

/// The sizes of the file [`super::to_bytes`] writes for `mlp` stored as `dtype` without a teacher
/// record (with one, [`Layout::with_extra_header`] of [`layout::TEACHER_LEN`]).
pub fn encoded_layout(mlp: &MlpWeights, dtype: StorageDtype) -> Layout {
    let dims: Vec<(u64, u64)> = mlp
        .layers
        .iter()
        .map(|l| (l.n_in as u64, l.n_out as u64))
        .collect();
    Layout::for_layers(mlp.n_inputs() as u64, dtype, &dims)
}

/// Everything the writer and the reader both require of a model.
fn validate_model(f: &ModelFile) -> Result<(), WeightError> {
    let mlp = &f.mlp;
    for (k, l) in mlp.layers.iter().enumerate() {
        finite_all(|| format!("layer {k} weight"), &l.weight)?;
        finite_all(|| format!("layer {k} bias"), &l.bias)?;
    }
    finite_all(|| "normalisation mean".into(), &mlp.norm.mean)?;
    finite_all(|| "normalisation scale".into(), &mlp.norm.scale)?;
    mlp.validate()?;
    if f.dtype != StorageDtype::F32 {
        for (k, l) in mlp.layers.iter().enumerate() {
            for (what, v) in [("weight", &l.weight), ("bias", &l.bias)] {
                if let Some(index) = v.iter().position(|&x| !round_one(x, f.dtype).is_finite()) {
                    return Err(WeightError::NonFinite {
                        field: format!("layer {k} {what} (overflows {:?})", f.dtype),
                        index,
                        value: v[index].into(),
                    });
                }
            }
        }
    }
    let m = &f.meta;
    let spec = &m.features;
    if spec.history == 0 {
        return Err(WeightError::Invalid {
            field: "history",
            value: "0".into(),
            reason: "must be at least 1",
        });
    }
    let blocks = layout::block_units(spec.set).len() as u64;
    let spec_inputs = blocks
        .saturating_mul(spec.history as u64)
        .saturating_add(u64::from(spec.temperature));
    inconsistent("n_inputs", spec_inputs, mlp.n_inputs() as u64)?;
    text_ok("joint_name", &m.joint_name, layout::JOINT_NAME_MAX)?;
    text_ok(
        "tool_version",
        &m.training.tool_version,
        layout::TOOL_VERSION_MAX,
    )?;
    finite("gear_ratio", m.gear_ratio.get())?;
    finite("kt_nm_per_a", m.kt_nm_per_a)?;
    if m.kt_nm_per_a <= 0.0 {
        return Err(WeightError::Invalid {
            field: "kt_nm_per_a",
            value: m.kt_nm_per_a.to_string(),
            reason: "must be positive (the sign lives in the gear ratio)",
        });
    }
    if let Some(s) = &m.scv {
        for (name, v) in [
            ("scv.kc", s.kc),
            ("scv.ka", s.ka),
            ("scv.kv", s.kv),
            ("scv.ks", s.ks),
            ("scv.vs", s.vs),
            ("scv.alpha", s.alpha),
        ] {
            finite(name, v)?;
        }
    }
    if let Some(r) = &m.training.input_range {
        validate_range(r, spec)?;
    }
    for (field, v) in [
        ("val_rmse_nm", m.training.val_rmse_nm),
        ("test_rmse_nm", m.training.test_rmse_nm),
        (
            "quant_max_error_nm",
            m.training.quant_max_error_nm.unwrap_or(f32::NAN),
        ),
    ] {
        let ok = v.is_nan() || (v.is_finite() && v >= 0.0);
        if !ok {
            return Err(WeightError::Invalid {
                field,
                value: v.to_string(),
                reason: "must be NaN (unknown) or finite and ≥ 0",
            });
        }
    }
    Ok(())
}

/// Every used slot finite with min ≤ max; every unused slot (blocks beyond the set's, temperature
/// without a temperature input) exactly `[0, 0]`.
fn validate_range(r: &super::InputRange, spec: &FeatureSpec) -> Result<(), WeightError> {
    let n_blocks = spec.set.n_blocks();
    let slots = r
        .blocks
        .iter()
        .enumerate()
        .map(|(k, s)| (k < n_blocks, s))
        .chain(std::iter::once((spec.temperature, &r.temperature)));
    for (used, s) in slots {
        let value = format!("[{}, {}]", s[0], s[1]);
        if !used {
            if s[0] != 0.0 || s[1] != 0.0 {
                return Err(WeightError::Invalid {
                    field: "input_range",
                    value,
                    reason: "an unused slot (no such block / no temperature input) must be [0, 0]",
                });
            }
        } else if !(s[0].is_finite() && s[1].is_finite() && s[0] <= s[1]) {
            return Err(WeightError::Invalid {
                field: "input_range",
                value,
                reason: "must be finite with min ≤ max",
            });
        }
    }
    Ok(())
}

fn put(b: &mut [u8], at: usize, v: &[u8]) {
    b[at..at + v.len()].copy_from_slice(v);
}

/// Validating encoder (see [`super::to_bytes`]).
pub(super) fn encode(f: &ModelFile) -> Result<Vec<u8>, WeightError> {
    validate_model(f)?;
    probe_output(f)?;
    let mlp = &f.mlp;
    let m = &f.meta;
    let teacher_len = if m.training.teacher_sha256.is_some() {
        layout::TEACHER_LEN as u64
    } else {
        0
    };
    let lay = encoded_layout(mlp, f.dtype).with_extra_header(teacher_len);
    // Sizes are within limits (validated), so the layout fits the header's fields and memory.
    let mut b = vec![0u8; lay.file_len as usize];
    put_format_fields(&mut b, f, &lay);
    put_meta_fields(&mut b, m);
    let at = put_header_tables(&mut b, f);
    debug_assert_eq!(at as u64, lay.header_len);
    let mut at = lay.payload_offset as usize;
    for (k, l) in mlp.layers.iter().enumerate() {
        let dtype = match f.dtype {
            StorageDtype::Int8 | StorageDtype::Int16 if k + 1 == mlp.layers.len() => {
                StorageDtype::F32
            }
            d => d,
        };
        at = put_layer(&mut b, at, l, dtype);
    }
    debug_assert_eq!(at as u64, lay.file_len);
    let crc = file_crc(&b);
    put(&mut b, off::CRC, &crc.to_le_bytes());
    Ok(b)
}

/// Writes the fixed header's format fields: magic, version, the lengths of `lay`, the feature set
/// and its units, the network's shape, dtype, output unit and filtering.
fn put_format_fields(b: &mut [u8], f: &ModelFile, lay: &Layout) {
    let mlp = &f.mlp;
    let m = &f.meta;
    put(b, off::MAGIC, &layout::MAGIC);
    put(b, off::VERSION_MAJOR, &layout::VERSION_MAJOR.to_le_bytes());
    put(b, off::VERSION_MINOR, &layout::VERSION_MINOR.to_le_bytes());
    put(b, off::HEADER_LEN, &(lay.header_len as u32).to_le_bytes());
    put(
        b,
        off::PAYLOAD_OFFSET,
        &(lay.payload_offset as u32).to_le_bytes(),
    );
    put(b, off::PAYLOAD_LEN, &lay.payload_len.to_le_bytes());
    put(b, off::FILE_LEN, &lay.file_len.to_le_bytes());
    let units = layout::block_units(m.features.set);
    put(
        b,
        off::FEATURE_SET,
        &layout::feature_set_code(m.features.set).to_le_bytes(),
    );
    b[off::N_BLOCKS] = units.len() as u8;
    b[off::TEMPERATURE] = u8::from(m.features.temperature);
    put(b, off::HISTORY, &(m.features.history as u32).to_le_bytes());
    put(b, off::N_INPUTS, &(mlp.n_inputs() as u32).to_le_bytes());
    b[off::N_LAYERS] = mlp.layers.len() as u8;
    b[off::DTYPE] = layout::dtype_code(f.dtype);
    b[off::OUTPUT_UNIT] = layout::OUTPUT_UNIT.code();
    b[off::FILTERING] = layout::filtering_code(m.training.filtering);
    for (i, u) in units.iter().enumerate() {
        b[off::BLOCK_UNITS + i] = u.code();
    }
    for (i, &f) in m.features.set.blocks().iter().enumerate() {
        b[off::BLOCK_FEATURES + i] = layout::feature_code(f);
    }
    if m.features.temperature {
        b[off::TEMPERATURE_UNIT] = layout::TEMPERATURE_UNIT.code();
    }
}

/// Writes the fixed header's model and training fields of `m`: gear ratio, kt, the SCV
/// parameters, the input range, the hashes, errors, creation time and names.
fn put_meta_fields(b: &mut [u8], m: &ModelMeta) {
    put(b, off::GEAR_RATIO, &m.gear_ratio.get().to_le_bytes());
    put(b, off::KT, &m.kt_nm_per_a.to_le_bytes());
    if let Some(s) = &m.scv {
        b[off::SCV_PRESENT] = 1;
        for (i, v) in [s.kc, s.ka, s.kv, s.ks, s.vs, s.alpha]
            .into_iter()
            .enumerate()
        {
            put(b, off::SCV + 8 * i, &v.to_le_bytes());
        }
    }
    if let Some(r) = &m.training.input_range {
        b[off::RANGE_PRESENT] = 1;
        let values = r.blocks.iter().chain(std::iter::once(&r.temperature));
        for (k, s) in values.enumerate() {
            put(b, off::INPUT_RANGE + 8 * k, &s[0].to_le_bytes());
            put(b, off::INPUT_RANGE + 8 * k + 4, &s[1].to_le_bytes());
        }
    }
    put(b, off::DATASET_SHA256, &m.training.dataset_sha256);
    if m.training.teacher_sha256.is_some() {
        b[off::TEACHER_PRESENT] = 1;
    }
    put(b, off::VAL_RMSE, &m.training.val_rmse_nm.to_le_bytes());
    put(
        b,
        off::QUANT_MAX_ERROR,
        &m.training
            .quant_max_error_nm
            .unwrap_or(f32::NAN)
            .to_le_bytes(),
    );
    put(b, off::TEST_RMSE, &m.training.test_rmse_nm.to_le_bytes());
    put(b, off::CREATED, &m.training.created_unix_s.to_le_bytes());
    put(b, off::JOINT_NAME, m.joint_name.as_bytes());
    put(b, off::TOOL_VERSION, m.training.tool_version.as_bytes());
}

/// Writes the header's variable part after the fixed header (the layer table, the
/// normalisation, the teacher's hash); returns where it ends.
fn put_header_tables(b: &mut [u8], f: &ModelFile) -> usize {
    let mlp = &f.mlp;
    let m = &f.meta;
    let mut at = layout::FIXED_HEADER_LEN;
    for l in &mlp.layers {
        put(b, at, &(l.n_in as u32).to_le_bytes());
        put(b, at + 4, &(l.n_out as u32).to_le_bytes());
        b[at + 8] = layout::activation_code(l.activation);
        at += layout::LAYER_ENTRY_LEN;
    }
    for v in mlp.norm.mean.iter().chain(&mlp.norm.scale) {
        put(b, at, &v.to_le_bytes());
        at += 4;
    }
    if let Some(t) = &m.training.teacher_sha256 {
        put(b, at, t);
        at += layout::TEACHER_LEN;
    }
    at
}

/// Writes layer `l`'s weights and biases in `dtype` at `at` of the payload (int8 and int16 with
/// one scale per output row before the biases); returns where they end.
fn put_layer(b: &mut [u8], mut at: usize, l: &DenseLayer, dtype: StorageDtype) -> usize {
    if dtype == StorageDtype::Int16 {
        let rows = l.weight.chunks(l.n_in.max(1));
        let scales: Vec<f32> = rows
            .clone()
            .map(crate::kernel::int16_channel_scale)
            .collect();
        for (row, &sc) in rows.zip(&scales) {
            for &v in row {
                put(b, at, &crate::kernel::int16_code(v, sc).to_le_bytes());
                at += 2;
            }
        }
        for &v in scales.iter().chain(&l.bias) {
            put(b, at, &v.to_le_bytes());
            at += 4;
        }
        return at;
    }
    if dtype == StorageDtype::Int8 {
        let rows = l.weight.chunks(l.n_in.max(1));
        let scales: Vec<f32> = rows
            .clone()
            .map(crate::kernel::int8_channel_scale)
            .collect();
        for (row, &sc) in rows.zip(&scales) {
            for &v in row {
                b[at] = crate::kernel::int8_code(v, sc) as u8;
                at += 1;
            }
        }
        for &v in scales.iter().chain(&l.bias) {
            put(b, at, &v.to_le_bytes());
            at += 4;
        }
        return at;
    }
    for &v in l.weight.iter().chain(&l.bias) {
        match dtype {
            StorageDtype::F32 | StorageDtype::Int8 | StorageDtype::Int16 => {
                put(b, at, &v.to_le_bytes())
            }
            StorageDtype::F16 => put(b, at, &f16::from_f32(v).to_le_bytes()),
            StorageDtype::Bf16 => put(b, at, &bf16::from_f32(v).to_le_bytes()),
        }
        at += dtype.size_bytes();
    }
    at
}

/// See [`super::probe_output`].
pub(super) fn probe_output(f: &ModelFile) -> Result<(), WeightError> {
    let mut net = crate::kernel::Mlp::new(&f.mlp, f.dtype)?;
    let norm = &f.mlp.norm;
    let neg: Vec<f32> = norm.scale.iter().map(|s| -s).collect();
    let zeros = vec![0.0f32; norm.mean.len()];
    let probes: [(&'static str, &[f32]); 4] = [
        ("x = 0", &zeros),
        ("x = mean", &norm.mean),
        ("x = +scale", &norm.scale),
        ("x = -scale", &neg),
    ];
    for (input, x) in probes {
        let value = net.forward(x);
        if !value.is_finite() {
            return Err(WeightError::NonFiniteOutput { input, value });
        }
    }
    Ok(())
}
