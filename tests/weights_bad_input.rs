//! `.fwt` weight files: round trips, the spec's size formula, and every kind of bad input the reader
//! must refuse with a typed error and without panicking.
//!
//! Offsets used to craft bytes by hand are taken from `docs/weights-format.md`, written out here on
//! purpose (not imported from the crate), so a drift between spec and code fails these tests.

use std::path::PathBuf;

use frictionless::features::{FeatureSet, FeatureSpec};
use frictionless::friction::ScvParams;
use frictionless::mlp::{MlpShapeError, StorageDtype};
use frictionless::random::{RandomMlpSpec, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::layout::VERSION_MINOR;
use frictionless::weights::{
    self, InputRange, ModelFile, ModelMeta, SignalFiltering, TrainingMeta, WeightError, from_bytes,
    inspect, to_bytes,
};

// Offsets from docs/weights-format.md.
const CRC_AT: usize = 12;
const FILE_LEN_AT: usize = 32;
const N_INPUTS_AT: usize = 48;
const N_LAYERS_AT: usize = 52;
const FIXED: usize = 320;
const ENTRY: usize = 16;

fn fix_crc(b: &mut [u8]) {
    b[CRC_AT..CRC_AT + 4].fill(0);
    let crc = crc32c::crc32c(b);
    b[CRC_AT..CRC_AT + 4].copy_from_slice(&crc.to_le_bytes());
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}
fn put_u64(b: &mut [u8], at: usize, v: u64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn align64(n: usize) -> usize {
    n.div_ceil(64) * 64
}

/// Spec formula: align64(320 + 16·L + 8·n_in) + n_params·dtype_size.
fn spec_file_len(sizes: &[usize], dtype_size: usize) -> usize {
    let n_params: usize = sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum();
    align64(FIXED + ENTRY * (sizes.len() - 1) + 8 * sizes[0]) + n_params * dtype_size
}

/// A model for `sizes`; an odd input count means H = (n−1)/2 plus temperature.
fn model(sizes: &[usize], dtype: StorageDtype, seed: u64) -> ModelFile {
    ModelFile {
        meta: ModelMeta {
            joint_name: "l_ankle_roll".into(),
            gear_ratio: GearRatio::new(-160.0).unwrap(),
            kt_nm_per_a: 0.066468037,
            features: FeatureSpec {
                set: FeatureSet::DeltaThetaJointVel,
                history: sizes[0] / 2,
                temperature: sizes[0] % 2 == 1,
            },
            scv: Some(ScvParams {
                kc: 0.5,
                ka: 200.0,
                kv: 0.8,
                ks: 0.7,
                vs: 0.05,
                alpha: 2.0,
            }),
            training: TrainingMeta {
                dataset_sha256: [0xab; 32],
                val_rmse_nm: 0.21,
                test_rmse_nm: f32::NAN,
                created_unix_s: 1_718_000_000,
                tool_version: "frictl 0.1.0".into(),
                filtering: SignalFiltering::Causal,
                input_range: None,
                quant_max_error_nm: None,
                teacher_sha256: None,
            },
        },
        dtype,
        mlp: seeded_mlp(&RandomMlpSpec::new(sizes), seed).unwrap(),
    }
}

/// A small valid file: 4 → 3 → 1, f16 (a few hundred bytes, so every-length/every-bit loops are fast).
fn small(dtype: StorageDtype) -> (ModelFile, Vec<u8>) {
    let m = model(&[4, 3, 1], dtype, 7);
    let b = to_bytes(&m).expect("small model encodes");
    (m, b)
}

/// NaN-aware equality of the metadata (test RMSE is NaN on purpose).
fn assert_meta_eq(a: &ModelMeta, b: &ModelMeta) {
    let mut a = a.clone();
    let mut b = b.clone();
    assert!(a.training.test_rmse_nm.is_nan() && b.training.test_rmse_nm.is_nan());
    a.training.test_rmse_nm = 0.0;
    b.training.test_rmse_nm = 0.0;
    assert_eq!(a, b);
}

#[test]
fn round_trip_f32_is_exact() {
    let m = model(&[10, 8, 6, 1], StorageDtype::F32, 1);
    let back = from_bytes(&to_bytes(&m).unwrap()).unwrap();
    assert_meta_eq(&back.meta, &m.meta);
    assert_eq!(back.dtype, StorageDtype::F32);
    assert_eq!(back.mlp, m.mlp);
}

fn check_rounded(dtype: StorageDtype, mantissa_bits: i32) {
    let m = model(&[10, 8, 6, 1], dtype, 2);
    let bytes = to_bytes(&m).unwrap();
    let back = from_bytes(&bytes).unwrap();
    assert_meta_eq(&back.meta, &m.meta);
    assert_eq!(back.dtype, dtype);
    // Normalisation is stored as f32: exact.
    assert_eq!(back.mlp.norm, m.mlp.norm);
    // Round-to-nearest: relative error ≤ 2^-(mantissa_bits+1) for normal values; an absolute floor
    // covers f16 subnormals (spacing 2^-24).
    let rel = 2f32.powi(-(mantissa_bits + 1));
    let mut n_changed = 0;
    for (lo, lb) in m.mlp.layers.iter().zip(&back.mlp.layers) {
        for (a, b) in lo
            .weight
            .iter()
            .chain(&lo.bias)
            .zip(lb.weight.iter().chain(&lb.bias))
        {
            assert!(
                (a - b).abs() <= a.abs() * rel + 2f32.powi(-25),
                "{dtype:?}: {a} → {b}"
            );
            n_changed += usize::from(a != b);
        }
    }
    assert!(
        n_changed > 0,
        "{dtype:?} must actually round random f32 values"
    );
    // Writing the decoded model again gives identical bytes (values are representable now).
    assert_eq!(to_bytes(&back).unwrap(), bytes);
    // round_to_dtype predicts what the reader returns.
    assert_eq!(weights::round_to_dtype(&m.mlp, dtype), back.mlp);
}

#[test]
fn round_trip_f16_within_rounding() {
    check_rounded(StorageDtype::F16, 10);
}

#[test]
fn round_trip_bf16_within_rounding() {
    check_rounded(StorageDtype::Bf16, 7);
}

/// int16 (format 1.4): hidden weights within half a channel step (`max |w| / 8191`), biases and the
/// output layer exact, re-encoding reproduces the bytes, the size follows the spec's int16 formula;
/// codes outside ±8191, a non-canonical scale, a zero scale with non-zero codes and int16 in a 1.3
/// file are refused.
#[test]
fn round_trip_int16_per_channel() {
    let sizes = [40, 268, 215, 1];
    let m = model(&sizes, StorageDtype::Int16, 19);
    let bytes = to_bytes(&m).unwrap();
    // Spec: hidden layers 2·n_in·n_out + 8·n_out bytes, output layer 4·(n_in + 1).
    let payload = (2 * 40 * 268 + 8 * 268) + (2 * 268 * 215 + 8 * 215) + 4 * (215 + 1);
    assert_eq!(bytes.len(), 704 + payload);
    assert_eq!(bytes[53], 5, "dtype code");
    assert_eq!(
        u16::from_le_bytes([bytes[10], bytes[11]]),
        VERSION_MINOR,
        "written minor"
    );
    let back = from_bytes(&bytes).unwrap();
    assert_eq!(back.dtype, StorageDtype::Int16);
    let n = m.mlp.layers.len();
    for (k, (lo, lb)) in m.mlp.layers.iter().zip(&back.mlp.layers).enumerate() {
        assert_eq!(lo.bias, lb.bias, "biases are f32");
        if k + 1 == n {
            assert_eq!(lo.weight, lb.weight, "the output layer is f32");
            continue;
        }
        for (ro, rb) in lo.weight.chunks(lo.n_in).zip(lb.weight.chunks(lb.n_in)) {
            let step = ro.iter().fold(0f32, |a, v| a.max(v.abs())) / 8191.0;
            for (a, b) in ro.iter().zip(rb) {
                // Half a step, plus the f32 rounding of code · scale.
                assert!(
                    (a - b).abs() <= 0.5 * step + 2.0 * f32::EPSILON * a.abs(),
                    "{a} → {b} (step {step})"
                );
            }
            assert!(ro != rb, "int16 must actually quantise");
        }
    }
    assert_eq!(to_bytes(&back).unwrap(), bytes);
    assert_eq!(
        weights::round_to_dtype(&m.mlp, StorageDtype::Int16),
        back.mlp
    );
    assert_eq!(
        weights::encoded_layout(&m.mlp, StorageDtype::Int16).file_len,
        bytes.len() as u64
    );
    // Layer 0's first code sits at 704; its first scale after 40·268 codes of 2 bytes.
    let scale_at = 704 + 2 * 40 * 268;
    let refused = |c: &mut Vec<u8>, field: &str| {
        fix_crc(c);
        match from_bytes(c) {
            Err(WeightError::Invalid { field: f, .. }) => assert_eq!(f, field),
            other => panic!(
                "expected {field} refused, got {:?}",
                other.map(|_| "accepted")
            ),
        }
    };
    let mut c = bytes.clone();
    c[704..706].copy_from_slice(&8192i16.to_le_bytes());
    refused(&mut c, "int16 code");
    let mut c = bytes.clone();
    c[704..706].copy_from_slice(&(-8192i16).to_le_bytes());
    refused(&mut c, "int16 code");
    // Row 0 of layer 0 with every code 1: its scale is no longer max |w| / 8191.
    let mut c = bytes.clone();
    for i in 0..40 {
        c[704 + 2 * i..706 + 2 * i].copy_from_slice(&1i16.to_le_bytes());
    }
    refused(&mut c, "int16 scale");
    // A zero scale with non-zero codes.
    let mut c = bytes.clone();
    c[scale_at..scale_at + 4].copy_from_slice(&0f32.to_le_bytes());
    refused(&mut c, "int16 code");
    let mut c = bytes.clone();
    c[scale_at..scale_at + 4].copy_from_slice(&(-1f32).to_le_bytes());
    refused(&mut c, "int16 scale");
    // int16 exists from 1.4 on.
    let mut c = bytes.clone();
    c[10..12].copy_from_slice(&3u16.to_le_bytes());
    refused(&mut c, "dtype");
}

/// int8 (format 1.3): hidden weights within half a channel step, biases and the output layer exact,
/// re-encoding the decoded model gives the same bytes, the size follows the spec's int8 formula, the
/// measured conversion error round-trips, and a negative or non-finite scale is refused.
#[test]
fn round_trip_int8_per_channel() {
    let sizes = [40, 268, 215, 1];
    let mut m = model(&sizes, StorageDtype::Int8, 9);
    m.meta.training.quant_max_error_nm = Some(0.0042);
    let bytes = to_bytes(&m).unwrap();
    // Spec: hidden layers n_in·n_out + 8·n_out bytes, output layer 4·(n_in + 1).
    let payload = (40 * 268 + 8 * 268) + (268 * 215 + 8 * 215) + 4 * (215 + 1);
    assert_eq!(bytes.len(), 704 + payload);
    assert_eq!(bytes.len(), 704 + 73_068);
    assert_eq!(bytes[53], 4, "dtype code");
    let back = from_bytes(&bytes).unwrap();
    assert_eq!(back.dtype, StorageDtype::Int8);
    assert_eq!(back.meta.training.quant_max_error_nm, Some(0.0042));
    let n = m.mlp.layers.len();
    for (k, (lo, lb)) in m.mlp.layers.iter().zip(&back.mlp.layers).enumerate() {
        assert_eq!(lo.bias, lb.bias, "biases are f32");
        if k + 1 == n {
            assert_eq!(lo.weight, lb.weight, "the output layer is f32");
            continue;
        }
        for (ro, rb) in lo.weight.chunks(lo.n_in).zip(lb.weight.chunks(lb.n_in)) {
            let step = ro.iter().fold(0f32, |a, v| a.max(v.abs())) / 127.0;
            for (a, b) in ro.iter().zip(rb) {
                assert!(
                    (a - b).abs() <= 0.5 * step * 1.0001,
                    "{a} → {b} (step {step})"
                );
            }
            assert!(ro != rb, "int8 must actually quantise");
        }
    }
    assert_eq!(to_bytes(&back).unwrap(), bytes);
    assert_eq!(
        weights::round_to_dtype(&m.mlp, StorageDtype::Int8),
        back.mlp
    );
    assert_eq!(
        weights::encoded_layout(&m.mlp, StorageDtype::Int8).file_len,
        bytes.len() as u64
    );
    // The first scale of layer 0 sits right after its 40·268 codes.
    let scale_at = 704 + 40 * 268;
    for (bad, what) in [(-1.0f32, "negative"), (f32::INFINITY, "infinite")] {
        let mut c = bytes.clone();
        c[scale_at..scale_at + 4].copy_from_slice(&bad.to_le_bytes());
        fix_crc(&mut c);
        assert!(
            matches!(
                from_bytes(&c),
                Err(WeightError::Invalid { .. } | WeightError::NonFinite { .. })
            ),
            "{what} scale accepted"
        );
    }
    // Non-canonical int8: a −128 code, a scale that is not its row's.
    let mut c = bytes.clone();
    c[704] = 0x80;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::Invalid {
            field: "int8 code",
            ..
        })
    ));
    let mut c = bytes.clone();
    // Row 0 of layer 0 with every code 1: its scale is no longer max |w| / 127.
    c[704..744].fill(1);
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::Invalid {
            field: "int8 scale",
            ..
        })
    ));
    // A zero scale with non-zero codes decodes to a zero row whose re-encoding has zero codes: refused
    // (found by the weights_reader fuzz target).
    for (scale, code) in [(0.0f32, 0xacu8), (0.0, 0x01)] {
        let mut c = bytes.clone();
        c[704..744].fill(0);
        c[704] = code;
        c[scale_at..scale_at + 4].copy_from_slice(&scale.to_le_bytes());
        fix_crc(&mut c);
        let refused = from_bytes(&c);
        assert!(
            matches!(
                refused,
                Err(WeightError::Invalid {
                    field: "int8 code" | "int8 scale",
                    ..
                })
            ),
            "scale {scale:e} with code {code:#x}: {:?}",
            refused.map(|_| "accepted")
        );
    }
    // A negative measured error is refused by the writer; in a 1.2 file the field is reserved.
    let mut w = m.clone();
    w.meta.training.quant_max_error_nm = Some(-1.0);
    assert!(to_bytes(&w).is_err());
    let (f, fb) = small(StorageDtype::F16);
    assert_eq!(
        from_bytes(&fb).unwrap().meta.training.quant_max_error_nm,
        None
    );
    let mut old = to_bytes(&f).unwrap();
    old[10..12].copy_from_slice(&2u16.to_le_bytes());
    old[QUANT_ERROR_AT..QUANT_ERROR_AT + 4].copy_from_slice(&0.5f32.to_le_bytes());
    fix_crc(&mut old);
    assert!(matches!(
        from_bytes(&old),
        Err(WeightError::NonZeroReserved {
            offset: 68..=71,
            ..
        })
    ));
    old[QUANT_ERROR_AT..QUANT_ERROR_AT + 4].fill(0);
    fix_crc(&mut old);
    assert_eq!(
        from_bytes(&old).unwrap().meta.training.quant_max_error_nm,
        None
    );
}

#[test]
fn ergocub_shape_round_trip_and_spec_size() {
    let sizes = [40, 268, 215, 1];
    for (dtype, size) in [
        (StorageDtype::F32, 4),
        (StorageDtype::F16, 2),
        (StorageDtype::Bf16, 2),
    ] {
        let m = model(&sizes, dtype, 3);
        let bytes = to_bytes(&m).unwrap();
        assert_eq!(bytes.len(), spec_file_len(&sizes, size), "{dtype:?}");
        let back = from_bytes(&bytes).unwrap();
        assert_eq!(back.mlp.sizes(), sizes.to_vec());
        assert_eq!(back.mlp.n_params(), 69_039);
        assert_eq!(
            weights::encoded_layout(&m.mlp, dtype).file_len,
            bytes.len() as u64
        );
        // Payload starts 64-aligned right after the header.
        let payload_offset = u32::from_le_bytes(bytes[20..24].try_into().unwrap()) as usize;
        assert_eq!(payload_offset % 64, 0);
        assert_eq!(payload_offset + 69_039 * size, bytes.len());
    }
    // The numbers quoted in docs/weights-format.md.
    assert_eq!(spec_file_len(&sizes, 4), 276_860);
    assert_eq!(spec_file_len(&sizes, 2), 138_782);
}

#[test]
fn truncated_at_every_length_is_an_error() {
    for dtype in [StorageDtype::F32, StorageDtype::F16] {
        let (_, b) = small(dtype);
        for len in 0..b.len() {
            let r = from_bytes(&b[..len]);
            assert!(
                matches!(
                    r,
                    Err(WeightError::Truncated { .. } | WeightError::HeaderSaysMore { .. })
                ),
                "len {len}: {r:?}"
            );
            // Inspect must not panic either; a complete header still gives a view.
            if let Ok(i) = inspect(&b[..len]) {
                assert!(i.error.is_some());
                assert_eq!(i.file_len, len as u64);
            }
        }
        assert!(from_bytes(&b).is_ok());
    }
}

#[test]
fn every_single_bit_flip_is_detected() {
    let (_, b) = small(StorageDtype::F16);
    let mut c = b.clone();
    for byte in 0..b.len() {
        for bit in 0..8 {
            c[byte] ^= 1 << bit;
            assert!(
                from_bytes(&c).is_err(),
                "flip of byte {byte} bit {bit} went undetected"
            );
            c[byte] ^= 1 << bit;
        }
    }
    assert_eq!(c, b);
}

#[test]
fn payload_bit_flip_is_a_crc_error() {
    let (_, mut b) = small(StorageDtype::F32);
    let last = b.len() - 1;
    b[last] ^= 0x10;
    assert!(matches!(from_bytes(&b), Err(WeightError::Crc { .. })));
}

#[test]
fn wrong_magic_and_version() {
    let (_, b) = small(StorageDtype::F32);
    let mut c = b.clone();
    c[0] = b'X';
    assert!(matches!(from_bytes(&c), Err(WeightError::BadMagic { .. })));
    assert!(matches!(inspect(&c), Err(WeightError::BadMagic { .. })));
    // Text-mode line-ending damage is caught by the magic.
    let mut c = b.clone();
    c[4] = b'\n';
    assert!(matches!(from_bytes(&c), Err(WeightError::BadMagic { .. })));
    assert!(matches!(
        from_bytes(b"PK\x03\x04"),
        Err(WeightError::BadMagic { .. })
    ));
    // Unknown major: refused even with a valid CRC.
    let mut c = b.clone();
    c[8..10].copy_from_slice(&2u16.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::UnsupportedVersion { major: 2, .. })
    ));
    assert!(matches!(
        inspect(&c),
        Err(WeightError::UnsupportedVersion { .. })
    ));
    let mut c = b.clone();
    c[8..10].copy_from_slice(&0u16.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::UnsupportedVersion { major: 0, .. })
    ));
}

/// The teacher record (format 1.5): a distilled model's teacher SHA-256 round-trips, lengthens the
/// header by 32 bytes (the payload moving to the next 64-byte step when it must), and shows in
/// `inspect`; a file without a teacher keeps the 1.4 layout; byte 67 (`teacher_present`) is refused
/// as non-zero reserved in a 1.4 file, and as an unknown flag value other than 0 or 1.
#[test]
fn teacher_record_round_trips_and_old_layout_stays() {
    let (m, plain) = small(StorageDtype::F32);
    assert_eq!(
        plain.len(),
        spec_file_len(&[4, 3, 1], 4),
        "no teacher: 1.4 layout"
    );
    assert_eq!(
        from_bytes(&plain).unwrap().meta.training.teacher_sha256,
        None
    );
    let mut t = m.clone();
    t.meta.training.teacher_sha256 = Some([0x5a; 32]);
    let bytes = to_bytes(&t).unwrap();
    assert_eq!(bytes[67], 1, "teacher_present");
    let header_len = FIXED + ENTRY * 2 + 8 * 4 + 32;
    assert_eq!(
        u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize,
        header_len
    );
    assert_eq!(&bytes[header_len - 32..header_len], &[0x5a; 32]);
    assert_eq!(
        bytes.len(),
        align64(header_len) + (4 * 3 + 3 + 3 + 1) * 4,
        "the record counts in header_len"
    );
    let back = from_bytes(&bytes).unwrap();
    assert_eq!(back.meta.training.teacher_sha256, Some([0x5a; 32]));
    assert_eq!(back.mlp, t.mlp);
    assert_eq!(to_bytes(&back).unwrap(), bytes);
    let seen = inspect(&bytes).unwrap();
    assert_eq!(
        seen.teacher_sha256.as_deref(),
        Some("5a".repeat(32).as_str())
    );
    assert!(seen.to_string().contains("teacher sha256"));
    // Larger model: the record pushes the payload offset to the next 64-byte step.
    let mut big = model(&[40, 16, 1], StorageDtype::Int16, 3);
    big.meta.training.teacher_sha256 = Some([7; 32]);
    let bb = to_bytes(&big).unwrap();
    assert_eq!(
        from_bytes(&bb).unwrap().meta.training.teacher_sha256,
        Some([7; 32])
    );
    // A 1.4 file: byte 67 is reserved.
    let mut old = plain.clone();
    old[10..12].copy_from_slice(&4u16.to_le_bytes());
    fix_crc(&mut old);
    assert!(
        from_bytes(&old).is_ok(),
        "a 1.4 file without a teacher reads"
    );
    old[67] = 1;
    fix_crc(&mut old);
    assert!(matches!(
        from_bytes(&old),
        Err(WeightError::NonZeroReserved { offset: 67, .. })
    ));
    // A flag of 1 without the 32 bytes, or a flag of 2, is refused.
    let mut c = plain.clone();
    c[67] = 1;
    fix_crc(&mut c);
    assert!(from_bytes(&c).is_err(), "flag set without the record");
    c[67] = 2;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::UnknownCode {
            field: "teacher_present",
            ..
        })
    ));
}

#[test]
fn newer_minor_is_read_and_may_use_reserved_bytes() {
    let (m, b) = small(StorageDtype::F32);
    // Minor 2 (the version this reader writes), no input range: a non-zero byte in the unused range
    // field (offsets 288 to the end of the fixed header) is refused.
    let mut c = b.clone();
    c[300] = 1;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::NonZeroReserved { offset: 300, .. })
    ));
    // Minor 7: same byte is a field this reader does not know; it is ignored.
    c[10..12].copy_from_slice(&7u16.to_le_bytes());
    fix_crc(&mut c);
    let back = from_bytes(&c).unwrap();
    assert_eq!(back.mlp, m.mlp);
    assert_eq!(inspect(&c).unwrap().version_minor, 7);
}

/// Builds a complete file by hand from the spec (no crate code), with the given layer table.
fn hand_file(
    n_inputs: u32,
    history: u32,
    layers: &[(u32, u32, u8)],
    dtype_code: u8,
    dtype_size: usize,
) -> Vec<u8> {
    let n_layers = layers.len();
    let header_len = FIXED + ENTRY * n_layers + 8 * n_inputs as usize;
    let payload_offset = align64(header_len);
    let n_params: u64 = layers
        .iter()
        .map(|&(i, o, _)| (u64::from(i) + 1) * u64::from(o))
        .sum();
    let payload_len = n_params * dtype_size as u64;
    let file_len = payload_offset as u64 + payload_len;
    // Keep the buffer to what the test can afford; the caller may claim more than is present.
    let present = (file_len as usize).min(header_len.max(payload_offset) + 4096);
    let mut b = vec![0u8; present];
    b[0..8].copy_from_slice(b"FWT\0\r\n\x1a\n");
    b[8..10].copy_from_slice(&1u16.to_le_bytes());
    put_u32(&mut b, 16, header_len as u32);
    put_u32(&mut b, 20, payload_offset as u32);
    put_u64(&mut b, 24, payload_len);
    put_u64(&mut b, FILE_LEN_AT, file_len);
    b[40..42].copy_from_slice(&2u16.to_le_bytes()); // [ω_m, ṡ]
    b[42] = 2; // blocks
    b[43] = 0; // no temperature
    put_u32(&mut b, 44, history);
    put_u32(&mut b, N_INPUTS_AT, n_inputs);
    b[N_LAYERS_AT] = n_layers as u8;
    b[53] = dtype_code;
    b[54] = 6; // Nm
    b[55] = 0; // filtering unknown
    b[56] = 4; // motor rad/s
    b[57] = 2; // rad/s
    b[72..80].copy_from_slice(&100.0f64.to_le_bytes());
    b[80..88].copy_from_slice(&0.111f64.to_le_bytes());
    b[168..172].copy_from_slice(&f32::NAN.to_le_bytes());
    b[172..176].copy_from_slice(&f32::NAN.to_le_bytes());
    b[184..190].copy_from_slice(b"r_knee");
    b[248..252].copy_from_slice(b"hand");
    for (k, &(i, o, a)) in layers.iter().enumerate() {
        let at = FIXED + ENTRY * k;
        put_u32(&mut b, at, i);
        put_u32(&mut b, at + 4, o);
        b[at + 8] = a;
    }
    let scale_at = FIXED + ENTRY * n_layers + 4 * n_inputs as usize;
    for j in 0..n_inputs as usize {
        if scale_at + 4 * j + 4 <= b.len() {
            b[scale_at + 4 * j..scale_at + 4 * j + 4].copy_from_slice(&1.0f32.to_le_bytes());
        }
    }
    fix_crc(&mut b);
    b
}

#[test]
fn hand_written_header_from_the_spec_is_accepted() {
    let b = hand_file(6, 3, &[(6, 5, 1), (5, 1, 2)], 2, 2);
    assert_eq!(b.len(), spec_file_len(&[6, 5, 1], 2));
    let m = from_bytes(&b).expect("a file written from the spec by hand");
    assert_eq!(m.meta.joint_name, "r_knee");
    assert_eq!(
        m.meta.features,
        FeatureSpec {
            set: FeatureSet::MotorVelJointVel,
            history: 3,
            temperature: false
        }
    );
    assert_eq!(m.meta.gear_ratio.get(), 100.0);
    assert_eq!(m.dtype, StorageDtype::F16);
    assert_eq!(m.mlp.sizes(), vec![6, 5, 1]);
    assert!(m.meta.scv.is_none());
    let i = inspect(&b).unwrap();
    assert!(i.crc_ok && i.error.is_none());
    assert_eq!(i.macs, 6 * 5 + 5);
}

#[test]
fn shapes_over_limits_are_refused_before_allocating() {
    use frictionless::mlp::limits::*;
    // A hidden layer wider than the limit, the file claiming a (huge) matching payload.
    let w = (MAX_WIDTH + 1) as u32;
    let b = hand_file(6, 3, &[(6, w, 1), (w, 1, 2)], 1, 4);
    let r = from_bytes(&b);
    assert!(
        matches!(
            r,
            Err(WeightError::Shape(MlpShapeError::Dimension {
                layer: 0,
                what: "n_out",
                ..
            }))
        ),
        "{r:?}"
    );
    assert!(inspect(&b).is_err());
    // An absurd width (4 G) in a tiny file.
    let b = hand_file(6, 3, &[(6, u32::MAX, 1), (u32::MAX, 1, 2)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Dimension { .. }))
    ));
    // Too many inputs.
    let n = (MAX_INPUTS + 2) as u32;
    let b = hand_file(n, n / 2, &[(n, 4, 1), (4, 1, 2)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Dimension {
            what: "n_in",
            ..
        }))
    ));
    // Too many outputs.
    let b = hand_file(6, 3, &[(6, 4, 1), (4, 2, 2)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Dimension {
            layer: 1,
            ..
        }))
    ));
    // Too deep: MAX_HIDDEN_LAYERS + 1 hidden layers.
    let mut layers = vec![(6, 4, 1u8)];
    layers.extend(std::iter::repeat_n((4, 4, 1u8), MAX_HIDDEN_LAYERS));
    layers.push((4, 1, 2));
    let b = hand_file(6, 3, &layers, 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::TooDeep(_)))
    ));
    // No layers.
    let b = hand_file(6, 3, &[], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Empty))
    ));
    // Layers that do not chain, and a ReLU output layer.
    let b = hand_file(6, 3, &[(6, 4, 1), (5, 1, 2)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Chain { layer: 1, .. }))
    ));
    let b = hand_file(6, 3, &[(6, 4, 1), (4, 1, 1)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Shape(MlpShapeError::Activation {
            layer: 1,
            ..
        }))
    ));
    // Unknown codes.
    let b = hand_file(6, 3, &[(6, 4, 1), (4, 1, 9)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::UnknownCode {
            field: "layer activation",
            value: 9
        })
    ));
    let b = hand_file(6, 3, &[(6, 4, 1), (4, 1, 2)], 6, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::UnknownCode {
            field: "dtype",
            value: 6
        })
    ));
    // History that does not match the input count.
    let b = hand_file(6, 2, &[(6, 4, 1), (4, 1, 2)], 1, 4);
    assert!(matches!(
        from_bytes(&b),
        Err(WeightError::Inconsistent {
            field: "n_inputs",
            ..
        })
    ));
}

#[test]
fn header_claiming_more_data_than_present() {
    // A consistent header (1000-wide hidden layer, 32 kB of f32 payload) with only 4 kB present.
    let b = hand_file(6, 3, &[(6, 1000, 1), (1000, 1, 2)], 1, 4);
    let claimed = spec_file_len(&[6, 1000, 1], 4) as u64;
    let r = from_bytes(&b);
    assert!(
        matches!(r, Err(WeightError::HeaderSaysMore { claimed: c, present: p }) if c == claimed && p == b.len() as u64),
        "{r:?}"
    );
    // inspect still shows the header and says what is wrong.
    let i = inspect(&b).unwrap();
    assert_eq!(i.expected_file_len, claimed);
    assert!(i.file_len < i.expected_file_len);
    assert!(i.error.as_deref().unwrap().contains("file_len"));
    // The small file cut after its header.
    let (_, b) = small(StorageDtype::F32);
    let payload = u32::from_le_bytes(b[20..24].try_into().unwrap()) as usize;
    assert!(matches!(
        from_bytes(&b[..payload]),
        Err(WeightError::HeaderSaysMore { .. })
    ));
    // Extra data at the end.
    let mut c = b.clone();
    c.extend_from_slice(&[0; 8]);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::TrailingData { .. })
    ));
    // Size keys that disagree with the shapes (valid CRC), including an absurd file_len.
    let len = b.len() as u64;
    for (at, v, field) in [
        (FILE_LEN_AT, len + 64, "file_len"),
        (FILE_LEN_AT, u64::MAX, "file_len"),
        (24, 1 << 40, "payload_len"),
    ] {
        let mut c = b.clone();
        put_u64(&mut c, at, v);
        fix_crc(&mut c);
        let r = from_bytes(&c);
        assert!(
            matches!(r, Err(WeightError::Inconsistent { field: f, .. }) if f == field),
            "{field}: {r:?}"
        );
    }
    let mut c = b.clone();
    put_u32(&mut c, 16, 1 << 30);
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::Inconsistent {
            field: "header_len",
            ..
        })
    ));
}

#[test]
fn writer_refuses_non_finite_values() {
    let base = model(&[4, 3, 1], StorageDtype::F32, 9);
    type Mutation = Box<dyn Fn(&mut ModelFile)>;
    let cases: Vec<(&str, Mutation)> = vec![
        (
            "weight NaN",
            Box::new(|m| m.mlp.layers[0].weight[2] = f32::NAN),
        ),
        (
            "bias +Inf",
            Box::new(|m| m.mlp.layers[1].bias[0] = f32::INFINITY),
        ),
        (
            "mean -Inf",
            Box::new(|m| m.mlp.norm.mean[1] = f32::NEG_INFINITY),
        ),
        ("scale NaN", Box::new(|m| m.mlp.norm.scale[3] = f32::NAN)),
        ("kt NaN", Box::new(|m| m.meta.kt_nm_per_a = f64::NAN)),
        (
            "scv Inf",
            Box::new(|m| m.meta.scv.as_mut().unwrap().vs = f64::INFINITY),
        ),
    ];
    for (what, f) in cases {
        let mut m = base.clone();
        f(&mut m);
        assert!(
            matches!(to_bytes(&m), Err(WeightError::NonFinite { .. })),
            "{what}"
        );
    }
    // A value that overflows f16 (max 65504) is refused when storing as f16, fine as bf16/f32.
    let mut m = base.clone();
    m.mlp.layers[0].weight[0] = 1.0e6;
    assert!(to_bytes(&m).is_ok());
    m.dtype = StorageDtype::Bf16;
    assert!(to_bytes(&m).is_ok());
    m.dtype = StorageDtype::F16;
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::NonFinite { index: 0, .. })
    ));
}

#[test]
fn reader_refuses_non_finite_values_with_a_valid_crc() {
    // f32 payload: first weight of layer 0 → NaN.
    let (_, b) = small(StorageDtype::F32);
    let payload = u32::from_le_bytes(b[20..24].try_into().unwrap()) as usize;
    let mut c = b.clone();
    c[payload..payload + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    fix_crc(&mut c);
    let r = from_bytes(&c);
    assert!(
        matches!(&r, Err(WeightError::NonFinite { field, index: 0, .. }) if field == "layer 0 weight"),
        "{r:?}"
    );
    // The view still works and reports the problem.
    let i = inspect(&c).unwrap();
    assert!(i.crc_ok);
    assert!(i.error.unwrap().contains("layer 0 weight"));
    // f16 payload: last value (output bias) → +Inf (0x7c00).
    let (_, b) = small(StorageDtype::F16);
    let mut c = b.clone();
    let n = c.len();
    c[n - 2..].copy_from_slice(&0x7c00u16.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(from_bytes(&c), Err(WeightError::NonFinite { .. })));
    // Normalisation mean (f32 in the header, after a 2-entry layer table) → -Inf.
    let (_, b) = small(StorageDtype::F16);
    let mut c = b.clone();
    let mean_at = FIXED + 2 * ENTRY;
    c[mean_at..mean_at + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(from_bytes(&c), Err(WeightError::NonFinite { .. })));
    // A zero scale is a shape error (division by zero in the normalisation).
    let mut c = b.clone();
    let scale_at = mean_at + 4 * 4;
    c[scale_at..scale_at + 4].copy_from_slice(&0f32.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::Shape(MlpShapeError::NonFinite { .. }))
    ));
}

#[test]
fn writer_refuses_bad_metadata() {
    let base = model(&[4, 3, 1], StorageDtype::F32, 9);
    let mut m = base.clone();
    m.meta.joint_name = "x".repeat(64);
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Invalid {
            field: "joint_name",
            ..
        })
    ));
    m.meta.joint_name = "é".repeat(31) + "a"; // 63 bytes of UTF-8: fits
    let back = from_bytes(&to_bytes(&m).unwrap()).unwrap();
    assert_eq!(back.meta.joint_name, m.meta.joint_name);
    let mut m = base.clone();
    m.meta.training.tool_version = "t".repeat(32);
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Invalid {
            field: "tool_version",
            ..
        })
    ));
    let mut m = base.clone();
    m.meta.joint_name = "a\0b".into();
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Invalid {
            field: "joint_name",
            ..
        })
    ));
    let mut m = base.clone();
    m.meta.kt_nm_per_a = -0.1;
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Invalid {
            field: "kt_nm_per_a",
            ..
        })
    ));
    let mut m = base.clone();
    m.meta.features.history = 3; // 2·3 = 6 inputs, network has 4
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Inconsistent {
            field: "n_inputs",
            stored: 6,
            expected: 4
        })
    ));
    let mut m = base.clone();
    m.meta.training.val_rmse_nm = -1.0;
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Invalid {
            field: "val_rmse_nm",
            ..
        })
    ));
    let mut m = base.clone();
    m.mlp.layers[0].weight.pop();
    assert!(matches!(
        to_bytes(&m),
        Err(WeightError::Shape(MlpShapeError::Length { .. }))
    ));
}

#[test]
fn reader_refuses_bad_text_and_gear_ratio() {
    let (_, b) = small(StorageDtype::F32);
    // Invalid UTF-8 in the joint name.
    let mut c = b.clone();
    c[184] = 0xff;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::BadUtf8 {
            field: "joint_name"
        })
    ));
    // Garbage after the terminating NUL.
    let mut c = b.clone();
    c[184 + 63] = b'x';
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::BadUtf8 {
            field: "joint_name"
        })
    ));
    // Zero gear ratio.
    let mut c = b.clone();
    c[72..80].copy_from_slice(&0f64.to_le_bytes());
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::Invalid {
            field: "gear_ratio",
            ..
        })
    ));
}

#[test]
fn temperature_and_feature_sets_round_trip() {
    // Offset of `block_features` (minor ≥ 1) from docs/weights-format.md.
    const BLOCK_FEATURES_AT: usize = 280;
    for set in FeatureSet::ALL {
        let n = set.n_blocks();
        let mut m = model(&[3 * n + 1, 5, 1], StorageDtype::F32, 4);
        m.meta.features = FeatureSpec {
            set,
            history: 3,
            temperature: true,
        };
        m.meta.scv = None;
        let bytes = to_bytes(&m).unwrap();
        assert_eq!(
            u16::from_le_bytes([bytes[10], bytes[11]]),
            VERSION_MINOR,
            "current minor"
        );
        assert_eq!(usize::from(bytes[42]), n, "n_blocks");
        // The header names each block, in order, unused slots zero.
        let codes: Vec<u8> = set
            .blocks()
            .iter()
            .map(|f| match f.name() {
                "delta-theta" => 1,
                "joint-vel" => 2,
                "motor-vel" => 3,
                "joint-pos" => 4,
                "motor-pos" => 5,
                other => panic!("no code for {other}"),
            })
            .collect();
        assert_eq!(&bytes[BLOCK_FEATURES_AT..BLOCK_FEATURES_AT + n], &codes[..]);
        assert!(
            bytes[BLOCK_FEATURES_AT + n..BLOCK_FEATURES_AT + 8]
                .iter()
                .all(|&b| b == 0)
        );
        let back = from_bytes(&bytes).unwrap();
        assert_eq!(back.meta.features, m.meta.features);
        let i = inspect(&bytes).unwrap();
        assert_eq!(i.blocks, set.blocks());
        assert_eq!(i.input_units.len(), n + 1, "{n} blocks + temperature");
        assert_eq!(i.input_units[n], weights::Unit::Celsius);
        let text = i.to_string();
        assert!(
            text.contains(&format!("features       {set}, H = 3")),
            "{text}"
        );
        for f in set.blocks() {
            assert!(
                text.contains(&format!("{} [{}] ×3", f.name(), f.unit())),
                "{text}"
            );
        }
        let json = serde_json::to_value(&i).unwrap();
        assert_eq!(json["features"]["set"], set.name());
        assert_eq!(json["blocks"][0], set.blocks()[0].name());

        // The same model as format 1.0 wrote it: minor 0, no block names; read as the same set.
        let mut old = bytes.clone();
        old[10..12].copy_from_slice(&0u16.to_le_bytes());
        old[BLOCK_FEATURES_AT..BLOCK_FEATURES_AT + 8].fill(0);
        old[QUANT_ERROR_AT..QUANT_ERROR_AT + 4].fill(0);
        fix_crc(&mut old);
        let back = from_bytes(&old).expect("a 1.0 file");
        assert_eq!(back.meta.features, m.meta.features);
        assert_eq!(inspect(&old).unwrap().blocks, set.blocks());
        // In 1.0 those bytes are reserved: non-zero is refused.
        old[BLOCK_FEATURES_AT] = codes[0];
        fix_crc(&mut old);
        assert!(matches!(
            from_bytes(&old),
            Err(WeightError::NonZeroReserved { offset: 280, .. })
        ));

        // Minor 1 with block names that disagree with the set code: refused, naming the key.
        let mut bad = bytes.clone();
        bad[BLOCK_FEATURES_AT + n - 1] = if codes[n - 1] == 5 { 4 } else { 5 };
        fix_crc(&mut bad);
        assert!(matches!(
            from_bytes(&bad),
            Err(WeightError::Inconsistent {
                field: "block_features",
                ..
            })
        ));
        let mut bad = bytes.clone();
        bad[BLOCK_FEATURES_AT + n] = 2; // a block past the set's last
        fix_crc(&mut bad);
        assert!(matches!(
            from_bytes(&bad),
            Err(WeightError::Inconsistent {
                field: "block_features",
                ..
            })
        ));
        let mut bad = bytes.clone();
        bad[BLOCK_FEATURES_AT] = 99;
        fix_crc(&mut bad);
        assert!(matches!(
            from_bytes(&bad),
            Err(WeightError::UnknownCode {
                field: "block_features",
                value: 99
            })
        ));
    }
}

#[test]
fn inspect_reports_bad_crc_and_serialises() {
    let (m, b) = small(StorageDtype::F16);
    let i = inspect(&b).unwrap();
    assert!(i.crc_ok && i.error.is_none());
    assert_eq!(i.crc_stored, i.crc_computed);
    assert_eq!(i.sizes, vec![4, 3, 1]);
    assert_eq!(i.n_params, m.mlp.n_params());
    assert_eq!(i.macs, 4 * 3 + 3);
    assert_eq!(i.file_len, b.len() as u64);
    assert_eq!(i.expected_file_len, b.len() as u64);
    assert_eq!(i.joint_name, "l_ankle_roll");
    assert_eq!(i.gear_ratio, -160.0);
    assert_eq!(i.norm_mean, m.mlp.norm.mean);
    let json = serde_json::to_value(&i).unwrap();
    assert_eq!(json["joint_name"], "l_ankle_roll");
    assert_eq!(json["dtype"], "f16");
    assert!(
        json["test_rmse_nm"].is_null(),
        "NaN RMSE serialises as null"
    );
    let text = i.to_string();
    assert!(
        text.contains("4 → 3 → 1") && text.contains("valid"),
        "{text}"
    );

    let mut c = b.clone();
    let last = c.len() - 1;
    c[last] ^= 1;
    let i = inspect(&c).unwrap();
    assert!(!i.crc_ok);
    assert_ne!(i.crc_stored, i.crc_computed);
    assert!(i.error.as_deref().unwrap().contains("CRC"));
    assert!(i.to_string().contains("MISMATCH"));
}

fn scratch_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "frictionless-weights-{name}-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn files_are_written_atomically_and_errors_name_the_path() {
    let dir = scratch_dir("files");
    let path = dir.join("knee.fwt");
    let (m, _) = small(StorageDtype::Bf16);
    weights::write_file(&path, &m).unwrap();
    let back = weights::read_file(&path).unwrap();
    assert_eq!(
        back.mlp,
        weights::round_to_dtype(&m.mlp, StorageDtype::Bf16)
    );
    // Overwrite in place; no temporary file left behind.
    weights::write_file(&path, &m).unwrap();
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("knee.fwt")]);
    // A bad model is refused without touching the existing file.
    let mut bad = m.clone();
    bad.mlp.layers[0].bias[0] = f32::NAN;
    let e = weights::write_file(&path, &bad).unwrap_err();
    assert!(e.to_string().contains("knee.fwt"), "{e}");
    assert!(matches!(e.kind(), WeightError::NonFinite { .. }));
    assert!(weights::read_file(&path).is_ok());
    // Missing file: Io with the path.
    let missing = dir.join("missing.fwt");
    let e = weights::read_file(&missing).unwrap_err();
    assert!(matches!(&e, WeightError::Io { path, .. } if path == &missing));
    assert!(e.to_string().contains("missing.fwt"));
    // Corrupt file: format error wrapped with the path.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[0] = 0;
    std::fs::write(&path, &bytes).unwrap();
    let e = weights::read_file(&path).unwrap_err();
    assert!(e.to_string().contains("knee.fwt"), "{e}");
    assert!(matches!(e.kind(), WeightError::BadMagic { .. }));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Valid seed files for the fuzzer (`fuzz/run.sh` sets `FWT_FUZZ_SEED_DIR`); always checks them.
#[test]
fn fuzz_seed_files_are_valid() {
    let seeds = [
        ("small_f32.fwt", model(&[4, 3, 1], StorageDtype::F32, 11)),
        ("small_f16.fwt", model(&[4, 3, 1], StorageDtype::F16, 12)),
        (
            "deep_bf16.fwt",
            model(&[6, 5, 4, 3, 1], StorageDtype::Bf16, 13),
        ),
        ("wide_f16.fwt", model(&[20, 40, 1], StorageDtype::F16, 14)),
        (
            "deep_int8.fwt",
            model(&[6, 5, 4, 3, 1], StorageDtype::Int8, 15),
        ),
        (
            "deep_int16.fwt",
            model(&[6, 5, 4, 3, 1], StorageDtype::Int16, 16),
        ),
    ];
    let dir = std::env::var_os("FWT_FUZZ_SEED_DIR").map(PathBuf::from);
    for (name, m) in seeds {
        let bytes = to_bytes(&m).unwrap();
        assert!(from_bytes(&bytes).is_ok(), "{name}");
        if let Some(d) = &dir {
            std::fs::create_dir_all(d).unwrap();
            std::fs::write(d.join(name), &bytes).unwrap();
        }
    }
}

/// A model path that is not a regular file (a FIFO nobody writes, `/dev/zero`, a
/// directory) is refused before anything is read: no blocking on the FIFO, no unbounded allocation.
#[test]
fn read_file_refuses_non_regular_files_before_reading() {
    let dir = scratch_dir("nonregular");
    let fifo = dir.join("model.fifo");
    let _ = std::fs::remove_file(&fifo);
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
    for path in [fifo.clone(), PathBuf::from("/dev/zero"), dir.clone()] {
        let e = weights::read_file(&path).unwrap_err();
        assert!(
            matches!(&e, WeightError::NotRegularFile { path: p, .. } if p == &path),
            "{}: {e}",
            path.display()
        );
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A regular file larger than any valid `.fwt` is refused from its size alone.
#[test]
fn read_file_refuses_files_over_the_format_maximum() {
    let dir = scratch_dir("huge");
    let path = dir.join("huge.fwt");
    let f = std::fs::File::create(&path).unwrap();
    f.set_len(weights::layout::MAX_FILE_LEN + 1).unwrap(); // sparse: no disk used
    drop(f);
    let e = weights::read_file(&path).unwrap_err();
    assert!(
        matches!(e.kind(), WeightError::TooLarge { len, max } if *len == weights::layout::MAX_FILE_LEN + 1 && *max == weights::layout::MAX_FILE_LEN),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The largest network the limits allow encodes within `MAX_FILE_LEN`.
#[test]
fn max_file_len_covers_the_largest_network() {
    use frictionless::mlp::limits;
    let mut sizes = vec![limits::MAX_INPUTS];
    sizes.extend(std::iter::repeat_n(
        limits::MAX_WIDTH,
        limits::MAX_HIDDEN_LAYERS,
    ));
    sizes.push(limits::MAX_OUTPUTS);
    let len = spec_file_len(&sizes, 4) as u64;
    assert!(len <= weights::layout::MAX_FILE_LEN, "{len}");
}

/// A model whose output is not finite on representative inputs (a tiny normalisation
/// scale, a huge weight) is refused by the reader, by `inspect` and by the writer.
#[test]
fn models_with_non_finite_output_are_refused() {
    let (m, good) = small(StorageDtype::F32);
    assert!(from_bytes(&good).is_ok());
    let n = m.mlp.norm.scale.len();
    let layers = m.mlp.layers.len();
    let scale_at = FIXED + ENTRY * layers + 4 * n;
    // 1e-45: a subnormal scale; every input normalises to ±inf (or NaN).
    let mut tiny = good.clone();
    tiny[scale_at..scale_at + 4].copy_from_slice(&1e-45f32.to_le_bytes());
    fix_crc(&mut tiny);
    let e = from_bytes(&tiny).unwrap_err();
    assert!(matches!(e, WeightError::NonFiniteOutput { .. }), "{e}");
    assert!(e.to_string().contains("not finite"), "{e}");
    let i = inspect(&tiny).unwrap();
    assert!(i.error.as_deref().unwrap_or("").contains("output"), "{i:?}");
    // A 3e38 weight in every first-layer row: the hidden sums overflow to inf.
    let mut huge = m.clone();
    for w in &mut huge.mlp.layers[0].weight {
        *w = 3e38;
    }
    for w in &mut huge.mlp.layers[1].weight {
        *w = 3e38;
    }
    let e = to_bytes(&huge).unwrap_err();
    assert!(matches!(e, WeightError::NonFiniteOutput { .. }), "{e}");
}

/// Offsets of the input range (format 1.2) from docs/weights-format.md.
const RANGE_PRESENT_AT: usize = 66;
/// `quant_max_error_nm` (f32, format 1.3; reserved zero before).
const QUANT_ERROR_AT: usize = 68;
const INPUT_RANGE_AT: usize = 288;

fn ranged() -> ModelFile {
    // [Δθ, ṡ] with H = 2 and temperature: 5 inputs.
    let mut m = model(&[5, 3, 1], StorageDtype::F32, 11);
    m.meta.training.input_range = Some(InputRange {
        blocks: [[-0.02, 0.03], [-1.5, 1.25], [0.0, 0.0]],
        temperature: [20.0, 45.5],
    });
    m
}

#[test]
fn input_range_round_trips_at_its_documented_offsets_and_prints() {
    let m = ranged();
    let b = to_bytes(&m).unwrap();
    assert_eq!(b[RANGE_PRESENT_AT], 1);
    let f = |k: usize| {
        let at = INPUT_RANGE_AT + 4 * k;
        f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
    };
    assert_eq!((f(0), f(1), f(2), f(3)), (-0.02, 0.03, -1.5, 1.25));
    assert_eq!((f(4), f(5), f(6), f(7)), (0.0, 0.0, 20.0, 45.5));
    let back = from_bytes(&b).unwrap();
    assert_eq!(back.meta.training.input_range, m.meta.training.input_range);
    let text = inspect(&b).unwrap().to_string();
    assert!(
        text.contains("input range    delta-theta [-0.02, 0.03] motor rad, joint-vel [-1.5, 1.25] rad/s, temperature [20, 45.5] °C"),
        "{text}"
    );
    // Without a range: flag 0, the field all zero, inspect says so.
    let (_, plain) = small(StorageDtype::F32);
    assert_eq!(plain[RANGE_PRESENT_AT], 0);
    assert!(plain[INPUT_RANGE_AT..FIXED].iter().all(|&x| x == 0));
    assert!(
        from_bytes(&plain)
            .unwrap()
            .meta
            .training
            .input_range
            .is_none()
    );
    assert!(
        inspect(&plain)
            .unwrap()
            .to_string()
            .contains("input range    none")
    );
}

#[test]
fn a_1_1_file_reads_without_a_range_and_refuses_range_bytes() {
    let b = to_bytes(&ranged()).unwrap();
    // As a 1.1 writer would have it: no range, minor 1.
    let mut old = b.clone();
    old[10..12].copy_from_slice(&1u16.to_le_bytes());
    old[QUANT_ERROR_AT..QUANT_ERROR_AT + 4].fill(0);
    old[RANGE_PRESENT_AT] = 0;
    old[INPUT_RANGE_AT..FIXED].fill(0);
    fix_crc(&mut old);
    assert!(
        from_bytes(&old)
            .unwrap()
            .meta
            .training
            .input_range
            .is_none()
    );
    // In 1.1 both fields are reserved: non-zero is refused.
    let mut c = old.clone();
    c[RANGE_PRESENT_AT] = 1;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::NonZeroReserved { offset: 66, .. })
    ));
    // A bad presence flag in 1.2 is an unknown code.
    let mut c = b.clone();
    c[RANGE_PRESENT_AT] = 2;
    fix_crc(&mut c);
    assert!(matches!(
        from_bytes(&c),
        Err(WeightError::UnknownCode {
            field: "range_present",
            value: 2
        })
    ));
}

#[test]
fn bad_input_ranges_are_refused_by_writer_and_reader() {
    let cases: [(&str, InputRange); 3] = [
        (
            "min > max",
            InputRange {
                blocks: [[1.0, -1.0], [0.0, 1.0], [0.0, 0.0]],
                temperature: [20.0, 30.0],
            },
        ),
        (
            "unused block slot set",
            InputRange {
                blocks: [[-1.0, 1.0], [0.0, 1.0], [0.0, 0.5]],
                temperature: [20.0, 30.0],
            },
        ),
        (
            "not finite",
            InputRange {
                blocks: [[-1.0, f32::INFINITY], [0.0, 1.0], [0.0, 0.0]],
                temperature: [20.0, 30.0],
            },
        ),
    ];
    let good = to_bytes(&ranged()).unwrap();
    for (what, r) in cases {
        let mut m = ranged();
        m.meta.training.input_range = Some(r);
        assert!(
            matches!(
                to_bytes(&m),
                Err(WeightError::Invalid {
                    field: "input_range",
                    ..
                })
            ),
            "writer accepted {what}"
        );
        // The same values patched into a good file: the reader refuses them too.
        let mut c = good.clone();
        let values = r.blocks.iter().chain(std::iter::once(&r.temperature));
        for (k, s) in values.enumerate() {
            let at = INPUT_RANGE_AT + 8 * k;
            c[at..at + 4].copy_from_slice(&s[0].to_le_bytes());
            c[at + 4..at + 8].copy_from_slice(&s[1].to_le_bytes());
        }
        fix_crc(&mut c);
        assert!(
            matches!(
                from_bytes(&c),
                Err(WeightError::Invalid {
                    field: "input_range",
                    ..
                })
            ),
            "reader accepted {what}"
        );
    }
    // Without a temperature input the temperature slot must be [0, 0].
    let mut m = model(&[4, 3, 1], StorageDtype::F32, 3);
    m.meta.training.input_range = Some(InputRange {
        blocks: [[-1.0, 1.0], [0.0, 1.0], [0.0, 0.0]],
        temperature: [20.0, 30.0],
    });
    assert!(to_bytes(&m).is_err());
}

#[test]
fn input_range_of_rows_is_per_block_and_the_margin_widens_it() {
    let spec = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: 2,
        temperature: true,
    };
    let rows: [&[f32]; 2] = [&[0.1, -0.2, 1.0, 2.0, 30.0], &[0.3, 0.0, -3.0, 0.5, 25.0]];
    let r = InputRange::from_rows(&spec, rows).unwrap();
    assert_eq!(r.blocks, [[-0.2, 0.3], [-3.0, 2.0], [0.0, 0.0]]);
    assert_eq!(r.temperature, [25.0, 30.0]);
    assert!(InputRange::from_rows(&spec, std::iter::empty()).is_none());
    let short: [&[f32]; 1] = [&[0.0; 4]];
    assert!(InputRange::from_rows(&spec, short).is_none());
    // Width 5: margin 0.1 accepts up to 0.5 beyond either end.
    assert!(InputRange::within([-3.0, 2.0], 2.49, 0.1));
    assert!(!InputRange::within([-3.0, 2.0], 2.51, 0.1));
    assert!(!InputRange::within([-3.0, 2.0], -3.51, 0.1));
    assert!(!InputRange::within([-3.0, 2.0], 2.01, 0.0));
    assert!(!InputRange::within([-3.0, 2.0], f32::NAN, 0.1));
}
