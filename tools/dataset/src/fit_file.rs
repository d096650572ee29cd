//! The fitted static model in the JSON of `frictl fit cv|scv|scv-code --json`, defined once:
//! [`FittedModel`] (the file's `model` tag and `params`) is what eval, train (the SCV prior), the
//! experiments and the demo read back; `frictl fit` writes it flattened into its report.
//!
//! What it is: the serde type, the reader ([`FittedModel::read`]) and the conversions the readers need
//! (to a [`JointModel`], to an SCV prior). The tag values are
//! `"Cv"`, `"Scv"` and `"ScvCode"`; a parameter stored as `null` reads as +∞ (serde_json writes
//! non-finite numbers as `null`).
//!
//! What it is not: the fitter (`frictionless-ident`) or the daemon's `[[joint]]` snippet `frictl fit`
//! prints.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction};
use frictionless::model::JointModel;
use serde::{Deserialize, Deserializer, Serialize};

/// Why a fit file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FitFileError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
    /// Not JSON, an unknown `model`, or `params` that do not fit it.
    #[error(
        "{path}: not a fit of `frictl fit --json` (keys `model` = \"Cv\" | \"Scv\" | \"ScvCode\" and `params`): {message}"
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// serde's message (names the key or the variant).
        message: String,
    },
}

/// A fitted static model: the `model` tag and its `params` (validated when read).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model")]
pub enum FittedModel {
    /// Coulomb–viscous.
    Cv {
        /// kc, ka, kv.
        #[serde(deserialize_with = "params_or_inf")]
        params: CvParams,
    },
    /// Stribeck–Coulomb–viscous, paper form.
    Scv {
        /// kc, ka, kv, ks, vs, alpha.
        #[serde(deserialize_with = "params_or_inf")]
        params: ScvParams,
    },
    /// Stribeck–Coulomb–viscous, the authors' code form.
    ScvCode {
        /// fc, fs, fv, vs.
        #[serde(deserialize_with = "params_or_inf")]
        params: ScvCodeParams,
    },
}

/// `params` as an object of [`StaticFriction::PARAM_NAMES`] (each required, no others; `null` = +∞),
/// validated by [`StaticFriction::from_params`].
fn params_or_inf<'de, D: Deserializer<'de>, P: StaticFriction>(d: D) -> Result<P, D::Error> {
    use serde::de::Error;
    let map = BTreeMap::<String, Option<f64>>::deserialize(d)?;
    if let Some(k) = map.keys().find(|k| !P::PARAM_NAMES.contains(&k.as_str())) {
        return Err(D::Error::custom(format!(
            "params.{k}: not a parameter of {} (expected {:?})",
            P::NAME,
            P::PARAM_NAMES
        )));
    }
    let values = P::PARAM_NAMES
        .iter()
        .map(|n| match map.get(*n) {
            Some(v) => Ok(v.unwrap_or(f64::INFINITY)),
            None => Err(D::Error::custom(format!("params.{n} missing"))),
        })
        .collect::<Result<Vec<f64>, _>>()?;
    P::from_params(&values).map_err(|e| D::Error::custom(format!("params: {e}")))
}

impl FittedModel {
    /// Reads the `model` and `params` of a fit file (other keys are ignored, so hand-written files
    /// with just these two read too).
    pub fn read(path: &Path) -> Result<Self, FitFileError> {
        let text =
            frictionless::regular_file::read_text(path).map_err(|source| FitFileError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        serde_json::from_str(&text).map_err(|e| FitFileError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// The tag: `Cv`, `Scv` or `ScvCode`.
    pub fn tag(&self) -> &'static str {
        match self {
            Self::Cv { .. } => "Cv",
            Self::Scv { .. } => "Scv",
            Self::ScvCode { .. } => "ScvCode",
        }
    }

    /// The model as an estimator.
    pub fn joint_model(&self) -> JointModel {
        match *self {
            Self::Cv { params } => JointModel::Cv(params),
            Self::Scv { params } => JointModel::Scv(params),
            Self::ScvCode { params } => JointModel::ScvCode(params),
        }
    }

    /// The model in SCV paper form: CV with ks = kc (the Stribeck term vanishes; vs = α = 1), the code
    /// form with ka = ∞ and α = 2.
    pub fn to_scv(&self) -> ScvParams {
        match *self {
            Self::Cv { params: c } => ScvParams {
                kc: c.kc,
                ka: c.ka,
                kv: c.kv,
                ks: c.kc,
                vs: 1.0,
                alpha: 1.0,
            },
            Self::Scv { params } => params,
            Self::ScvCode { params } => ScvParams::from(params),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_files_null_as_infinity_and_errors() {
        let m: FittedModel = serde_json::from_str(
            r#"{"model": "Cv", "params": {"kc": 1.0, "ka": null, "kv": 0.5}}"#,
        )
        .unwrap();
        assert_eq!(
            m,
            FittedModel::Cv {
                params: CvParams {
                    kc: 1.0,
                    ka: f64::INFINITY,
                    kv: 0.5
                }
            }
        );
        assert_eq!(m.to_scv().ks, 1.0);
        let code: FittedModel = serde_json::from_str(
            r#"{"model": "ScvCode", "params": {"fc": 1.0, "fs": 2.0, "fv": 0.5, "vs": 0.1}}"#,
        )
        .unwrap();
        assert_eq!(code.to_scv().alpha, 2.0);
        assert!(matches!(code.joint_model(), JointModel::ScvCode(_)));
        for (bad, needle) in [
            (r#"{"model": "Lugre", "params": {}}"#, "Lugre"),
            (
                r#"{"model": "Cv", "params": {"kc": 1.0, "kv": 0.5}}"#,
                "params.ka",
            ),
            (
                r#"{"model": "Cv", "params": {"kc": 1.0, "ka": 1.0, "kv": 0.5, "ks": 1.0}}"#,
                "params.ks",
            ),
            (
                r#"{"model": "Cv", "params": {"kc": -1.0, "ka": 1.0, "kv": 0.5}}"#,
                "kc",
            ),
            (r#"{"params": {"kc": 1.0, "ka": 1.0, "kv": 0.5}}"#, "model"),
        ] {
            let e = serde_json::from_str::<FittedModel>(bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }
}
