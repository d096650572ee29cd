//! The fitted static model in the JSON of `frictl fit cv|scv|scv-code --json`, defined once:
//! [`FittedModel`] (the file's `model` tag and `params`) is what eval, train (the SCV prior), the
//! experiments and the demo read back; `frictl fit` writes it flattened into its report.
//!
//! What it is: the serde type, the reader ([`FittedModel::read`]) and the conversions the readers need
//! (to a [`JointModel`], to an SCV prior). The tag values are the core's
//! [`ModelKind::fit_tag`]s (`"Cv"`, `"Scv"`, `"ScvCode"`); a parameter stored as `null` reads as +∞
//! (serde_json writes non-finite numbers as `null`).
//!
//! What it is not: the fitter (`frictionless-ident`) or the daemon's `[[joint]]` snippet `frictl fit`
//! prints.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction};
use frictionless::lugre::{DEFAULT_DT_S, LugreEstimator, LugreParams};
use frictionless::model::{JointModel, ModelKind};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

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
        "{path}: not a fit of `frictl fit --json` (keys `model` = {tags} and `params`): {message}",
        tags = fit_tags()
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// serde's message (names the key or the variant).
        message: String,
    },
}

/// Why [`FittedModel::read_cv`] or [`FittedModel::read_scv`] cannot use a fit file.
#[derive(Debug, thiserror::Error)]
pub enum ReadModelError {
    /// The file cannot be read as a fit.
    #[error(transparent)]
    File(#[from] FitFileError),
    /// A fit of another model than the reader needs.
    #[error("{}: a fit of model {found:?}, {needed}", path.display())]
    WrongModel {
        /// The file.
        path: PathBuf,
        /// Its `model` tag.
        found: &'static str,
        /// What the reader needs (e.g. "--cv needs a CV fit (`frictl fit cv`)").
        needed: &'static str,
    },
}

/// The fit-file tags of the core's model list, quoted and `|`-separated (for messages).
pub fn fit_tags() -> String {
    ModelKind::ALL
        .iter()
        .filter_map(|k| k.fit_tag())
        .map(|t| format!("\"{t}\""))
        .collect::<Vec<_>>()
        .join(" | ")
}

/// A fitted static model: the `model` tag ([`ModelKind::fit_tag`]) and its `params` (validated when
/// read).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FittedModel {
    /// Coulomb–viscous.
    Cv {
        /// kc, ka, kv.
        params: CvParams,
    },
    /// Stribeck–Coulomb–viscous, paper form.
    Scv {
        /// kc, ka, kv, ks, vs, alpha.
        params: ScvParams,
    },
    /// Stribeck–Coulomb–viscous, the authors' code form.
    ScvCode {
        /// fc, fs, fv, vs.
        params: ScvCodeParams,
    },
    /// LuGre: the SCV curve's kc, kv, ks, vs, alpha and the bristle sigma0, sigma1.
    Lugre {
        /// kc, kv, ks, vs, alpha, sigma0, sigma1 (all finite).
        params: LugreParams,
    },
}

/// `params` as an object of [`StaticFriction::PARAM_NAMES`] (each required, no others; `null` = +∞),
/// validated by [`StaticFriction::from_params`].
fn params_or_inf<P: StaticFriction, E: serde::de::Error>(
    params: serde_json::Value,
) -> Result<P, E> {
    let map = BTreeMap::<String, Option<f64>>::deserialize(params)
        .map_err(|e| E::custom(format!("params: {e}")))?;
    if let Some(k) = map.keys().find(|k| !P::PARAM_NAMES.contains(&k.as_str())) {
        return Err(E::custom(format!(
            "params.{k}: not a parameter of {} (expected {:?})",
            P::NAME,
            P::PARAM_NAMES
        )));
    }
    let values = P::PARAM_NAMES
        .iter()
        .map(|n| match map.get(*n) {
            Some(v) => Ok(v.unwrap_or(f64::INFINITY)),
            None => Err(E::custom(format!("params.{n} missing"))),
        })
        .collect::<Result<Vec<f64>, _>>()?;
    P::from_params(&values).map_err(|e| E::custom(format!("params: {e}")))
}

impl Serialize for FittedModel {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(2))?;
        m.serialize_entry("model", self.tag())?;
        match self {
            Self::Cv { params } => m.serialize_entry("params", params)?,
            Self::Scv { params } => m.serialize_entry("params", params)?,
            Self::ScvCode { params } => m.serialize_entry("params", params)?,
            Self::Lugre { params } => m.serialize_entry("params", params)?,
        }
        m.end()
    }
}

/// The two keys a fit file is read by (other keys are ignored).
#[derive(Deserialize)]
struct Tagged {
    model: String,
    params: serde_json::Value,
}

impl<'de> Deserialize<'de> for FittedModel {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let Tagged { model, params } = Tagged::deserialize(d)?;
        let unknown = || {
            D::Error::custom(format!(
                "unknown model `{model}`, expected one of: {}",
                fit_tags()
            ))
        };
        match ModelKind::from_fit_tag(&model).ok_or_else(unknown)? {
            ModelKind::Cv => Ok(Self::Cv {
                params: params_or_inf::<_, D::Error>(params)?,
            }),
            ModelKind::Scv => Ok(Self::Scv {
                params: params_or_inf::<_, D::Error>(params)?,
            }),
            ModelKind::ScvCode => Ok(Self::ScvCode {
                params: params_or_inf::<_, D::Error>(params)?,
            }),
            ModelKind::Lugre => {
                let params = LugreParams::deserialize(params)
                    .map_err(|e| D::Error::custom(format!("params: {e}")))?;
                params
                    .validate()
                    .map_err(|e| D::Error::custom(format!("params.{}: {e}", e.name)))?;
                Ok(Self::Lugre { params })
            }
            ModelKind::None | ModelKind::Pinn => Err(unknown()),
        }
    }
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

    /// The model's kind in the core's list.
    pub fn kind(&self) -> ModelKind {
        match self {
            Self::Cv { .. } => ModelKind::Cv,
            Self::Scv { .. } => ModelKind::Scv,
            Self::ScvCode { .. } => ModelKind::ScvCode,
            Self::Lugre { .. } => ModelKind::Lugre,
        }
    }

    /// Reads a CV fit (`frictl fit cv --json`); a fit of another model is
    /// [`ReadModelError::WrongModel`].
    pub fn read_cv(path: &Path) -> Result<CvParams, ReadModelError> {
        match Self::read(path)? {
            Self::Cv { params } => Ok(params),
            other => Err(ReadModelError::WrongModel {
                path: path.to_path_buf(),
                found: other.tag(),
                needed: "--cv needs a CV fit (`frictl fit cv`)",
            }),
        }
    }

    /// Reads the SCV parameters of an SCV fit (`frictl fit scv --json`; `scv-code` in paper form,
    /// LuGre's curve); a CV fit is [`ReadModelError::WrongModel`].
    pub fn read_scv(path: &Path) -> Result<ScvParams, ReadModelError> {
        match Self::read(path)? {
            cv @ Self::Cv { .. } => Err(ReadModelError::WrongModel {
                path: path.to_path_buf(),
                found: cv.tag(),
                needed: "--scv needs an SCV fit (`frictl fit scv`)",
            }),
            scv => Ok(scv.to_scv()),
        }
    }

    /// The file's `model` tag ([`ModelKind::fit_tag`]): `Cv`, `Scv` or `ScvCode`.
    pub fn tag(&self) -> &'static str {
        self.kind().fit_tag().unwrap_or("")
    }

    /// The model as an estimator.
    pub fn joint_model(&self) -> JointModel {
        match *self {
            Self::Cv { params } => JointModel::Cv(params),
            Self::Scv { params } => JointModel::Scv(params),
            Self::ScvCode { params } => JointModel::ScvCode(params),
            // Integrated at the datasets' 1 kHz (the daemon's tick); the parameters were validated
            // when read, so `new` cannot fail (no compensation if it ever did).
            Self::Lugre { params } => LugreEstimator::new(params, DEFAULT_DT_S)
                .map(JointModel::Lugre)
                .unwrap_or_default(),
        }
    }

    /// The model in SCV paper form: CV with ks = kc (the Stribeck term vanishes; vs = α = 1), the code
    /// form with ka = ∞ and α = 2, LuGre's steady state (ka = ∞).
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
            Self::Lugre { params: l } => ScvParams {
                kc: l.kc,
                ka: f64::INFINITY,
                kv: l.kv,
                ks: l.ks,
                vs: l.vs,
                alpha: l.alpha,
            },
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
        let lugre: FittedModel = serde_json::from_str(
            r#"{"model": "Lugre", "params": {"kc": 1.0, "kv": 0.2, "ks": 1.5, "vs": 0.05, "alpha": 1.0, "sigma0": 1000.0, "sigma1": 2.0}}"#,
        )
        .unwrap();
        assert!(matches!(lugre.joint_model(), JointModel::Lugre(_)));
        assert_eq!(lugre.to_scv().ka, f64::INFINITY);
        let again: FittedModel =
            serde_json::from_str(&serde_json::to_string(&lugre).unwrap()).unwrap();
        assert_eq!(again, lugre);
        for (bad, needle) in [
            (r#"{"model": "Dahl", "params": {}}"#, "Dahl"),
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
            (
                r#"{"model": "Lugre", "params": {"kc": 1.0, "kv": 0.2, "ks": 1.5, "vs": 0.05, "alpha": 1.0, "sigma0": 0.0, "sigma1": 2.0}}"#,
                "params.sigma0",
            ),
        ] {
            let e = serde_json::from_str::<FittedModel>(bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }
}
