//! # `frictionless-interop`: ONNX and safetensors import/export of friction MLPs
//!
//! Crate table: `tools/interop`; depends on `frictionless`, onnx-protobuf (with its pinned protobuf) and
//! safetensors; used by `frictl` (`import`, `export`, `convert`) and the trainer's tests.
//!
//! What this crate **is**: conversion between [`frictionless::mlp::MlpWeights`] (the network inside a
//! `.fwt` file) and the two formats other tools speak:
//! - [`onnx`]: PyTorch-exported ONNX graphs (`Gemm`/`MatMul`+`Add`/`Relu` chains, with the authors'
//!   normalisation folded into a leading diagonal `Gemm`) in, and a plain `Gemm`/`Relu` graph out, so a
//!   model can be checked with ONNX Runtime.
//! - [`safetensors`]: PyTorch `nn.Sequential` state dicts (`0.weight`, `0.bias`, `2.weight`, …) in and out.
//!
//! Both directions also carry optional model metadata ([`ModelHints`]: joint name, signed gear ratio,
//! k_t, feature set) as string key/value pairs (ONNX `metadata_props`, safetensors `__metadata__`), so
//! an exported file can be re-imported without repeating them on the command line.
//!
//! What it is **not**: no inference engine (use [`frictionless::kernel::Mlp`]), no `.fwt` byte codec
//! (that is [`frictionless::weights`]), no general ONNX runtime: anything that is not a single
//! input→output chain of dense layers and ReLUs is refused with an error naming the node.
//!
//! ## Example: `.fwt` → ONNX bytes → back, same outputs
//! ```
//! use frictionless::kernel::Mlp;
//! use frictionless::mlp::StorageDtype;
//! use frictionless_interop::onnx::{self, ExportOptions};
//! use frictionless_interop::{ModelHints, max_output_change, random_inputs};
//!
//! // A shipped paper-size network (40 → 268 → 215 → 1, r = −160).
//! let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/models/stress32_paper_f16_r-160.fwt");
//! let file = frictionless::weights::read_file(std::path::Path::new(path))?;
//!
//! // Export with the model's metadata, so a re-import knows the joint without extra flags.
//! let opts = ExportOptions {
//!     metadata: ModelHints::from_meta(&file.meta).to_pairs(),
//!     ..ExportOptions::default()
//! };
//! let bytes = onnx::export_bytes(&file.mlp, &opts)?;
//! let back = onnx::import_bytes(&bytes)?;
//! assert_eq!(back.mlp.sizes(), file.mlp.sizes());
//! let hints = ModelHints::from_pairs(&back.metadata).expect("metadata written by us parses");
//! assert_eq!(hints.gear_ratio, Some(-160.0));
//!
//! // Both run on the core's kernel: f32 weights survive the trip exactly.
//! let mut a = Mlp::new(&file.mlp, StorageDtype::F32)?;
//! let mut b = Mlp::new(&back.mlp, StorageDtype::F32)?;
//! let inputs = random_inputs(&file.mlp.norm, 16, 7);
//! let (max_diff, max_ref) = max_output_change(&mut a, &mut b, &inputs);
//! assert!(max_ref > 0.0, "the network is not constant zero");
//! assert!(max_diff <= 1e-6 * max_ref, "max |Δ| = {max_diff} of {max_ref}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod onnx;
pub mod safetensors;

/// Largest ONNX or safetensors file an import reads (256 MiB): a friction MLP within
/// [`frictionless::mlp::limits`] is a few MB; anything far larger is not one, and is refused before
/// it is read (as is a FIFO or a device: see [`frictionless::regular_file`]).
pub const MAX_IMPORT_BYTES: u64 = 256 << 20;

use std::collections::BTreeMap;

use frictionless::features::{FeatureSet, FeatureSpec};
use frictionless::kernel::Mlp;
use frictionless::mlp::Normalisation;
use frictionless::weights::ModelMeta;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Metadata key prefix used in exported ONNX `metadata_props` and safetensors `__metadata__`.
pub const META_PREFIX: &str = "frictionless.";

/// Model metadata found in (or written to) an interchange file; every field is optional because
/// foreign files usually carry none of it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelHints {
    /// Joint name, e.g. "l_ankle_roll".
    pub joint_name: Option<String>,
    /// Signed gear ratio r (motor angle per joint angle).
    pub gear_ratio: Option<f64>,
    /// Torque constant k_t [Nm/A].
    pub kt_nm_per_a: Option<f64>,
    /// Feature set of the input vector.
    pub features: Option<FeatureSet>,
    /// History length H.
    pub history: Option<usize>,
    /// Whether the motor temperature is the last input.
    pub temperature: Option<bool>,
}

impl ModelHints {
    /// The hints a complete `.fwt` model carries.
    pub fn from_meta(meta: &ModelMeta) -> Self {
        let FeatureSpec {
            set,
            history,
            temperature,
        } = meta.features;
        Self {
            joint_name: Some(meta.joint_name.clone()),
            gear_ratio: Some(meta.gear_ratio.get()),
            kt_nm_per_a: Some(meta.kt_nm_per_a),
            features: Some(set),
            history: Some(history),
            temperature: Some(temperature),
        }
    }

    /// Key/value pairs (keys prefixed with [`META_PREFIX`]); numbers in Rust's round-trip format.
    pub fn to_pairs(&self) -> Vec<(String, String)> {
        let mut v = Vec::new();
        let mut put = |k: &str, val: Option<String>| {
            if let Some(val) = val {
                v.push((format!("{META_PREFIX}{k}"), val));
            }
        };
        put("joint_name", self.joint_name.clone());
        put("gear_ratio", self.gear_ratio.map(|r| format!("{r:?}")));
        put("kt_nm_per_a", self.kt_nm_per_a.map(|k| format!("{k:?}")));
        put("features", self.features.map(|s| s.name().to_string()));
        put("history", self.history.map(|h| h.to_string()));
        put("temperature", self.temperature.map(|t| t.to_string()));
        v
    }

    /// Reads the hints back from key/value pairs. Unknown keys are ignored; a known key with a value
    /// that does not parse is reported as `Err((key, value))`.
    pub fn from_pairs(pairs: &BTreeMap<String, String>) -> Result<Self, (String, String)> {
        let mut h = Self::default();
        for (k, v) in pairs {
            let Some(key) = k.strip_prefix(META_PREFIX) else {
                continue;
            };
            let bad = || (k.clone(), v.clone());
            match key {
                "joint_name" => h.joint_name = Some(v.clone()),
                "gear_ratio" => h.gear_ratio = Some(v.parse().map_err(|_| bad())?),
                "kt_nm_per_a" => h.kt_nm_per_a = Some(v.parse().map_err(|_| bad())?),
                "features" => h.features = Some(FeatureSet::parse(v).map_err(|_| bad())?),
                "history" => h.history = Some(v.parse().map_err(|_| bad())?),
                "temperature" => h.temperature = Some(v.parse().map_err(|_| bad())?),
                _ => {}
            }
        }
        Ok(h)
    }
}

/// `count` raw input vectors `mean + scale·z`, z ~ N(0, 1) (the region a model was trained on),
/// reproducible from `seed` (ChaCha8).
pub fn random_inputs(norm: &Normalisation, count: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            norm.mean
                .iter()
                .zip(&norm.scale)
                .map(|(&m, &s)| {
                    let z: f32 = StandardNormal.sample(&mut rng);
                    m + s * z
                })
                .collect()
        })
        .collect()
}

/// Largest |a(x) − b(x)| over `inputs`, and the largest |a(x)| (to judge it relatively).
/// Non-finite outputs make the result NaN.
pub fn max_output_change(a: &mut Mlp, b: &mut Mlp, inputs: &[Vec<f32>]) -> (f32, f32) {
    let mut max_diff = 0f32;
    let mut max_ref = 0f32;
    for x in inputs {
        let (ya, yb) = (a.forward(x), b.forward(x));
        if !ya.is_finite() || !yb.is_finite() {
            return (f32::NAN, f32::NAN);
        }
        max_diff = max_diff.max((ya - yb).abs());
        max_ref = max_ref.max(ya.abs());
    }
    (max_diff, max_ref)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hints_round_trip_through_pairs() {
        let h = ModelHints {
            joint_name: Some("l_ankle_roll".into()),
            gear_ratio: Some(-160.0),
            kt_nm_per_a: Some(0.066468037),
            features: Some(FeatureSet::JointPosMotorPos),
            history: Some(25),
            temperature: Some(false),
        };
        let map: BTreeMap<String, String> = h.to_pairs().into_iter().collect();
        assert_eq!(ModelHints::from_pairs(&map).unwrap(), h);
    }

    #[test]
    fn hints_reject_unparsable_values() {
        let mut map = BTreeMap::new();
        map.insert(format!("{META_PREFIX}gear_ratio"), "minus160".to_string());
        let err = ModelHints::from_pairs(&map).unwrap_err();
        assert_eq!(err.1, "minus160");
        map.clear();
        map.insert(format!("{META_PREFIX}features"), "torque".to_string());
        assert!(ModelHints::from_pairs(&map).is_err());
        map.clear();
        map.insert("producer".into(), "x".into());
        assert_eq!(ModelHints::from_pairs(&map).unwrap(), ModelHints::default());
    }

    #[test]
    fn feature_names_are_the_core_names_and_old_files_still_parse() {
        for s in FeatureSet::ALL {
            let h = ModelHints {
                features: Some(s),
                ..ModelHints::default()
            };
            let pairs = h.to_pairs();
            assert_eq!(
                pairs,
                vec![(format!("{META_PREFIX}features"), s.name().to_string())]
            );
            let json = serde_json::to_string(&s).unwrap();
            assert_eq!(json, format!("\"{}\"", s.name()));
            // Files exported before the hyphenated names carry the underscore spelling.
            let mut map = BTreeMap::new();
            map.insert(format!("{META_PREFIX}features"), s.name().replace('-', "_"));
            assert_eq!(ModelHints::from_pairs(&map).unwrap().features, Some(s));
        }
    }
}
