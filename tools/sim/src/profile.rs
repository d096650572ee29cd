//! Open-loop current profiles for `frictl sim run`.
//!
//! What it is: [`CurrentProfile`], a current reference i_ref(t) in the robot's convention (joint torque
//! = r_signed·k_t·i), parsed from a short text spec:
//! - `const:I` — constant I [A];
//! - `sine:A,F[,I0]` — I0 + A·sin(2π·F·t) [A, Hz, A];
//! - `step:L,T_ON[,T_OFF]` — L from T_ON until T_OFF (∞ if absent), else 0 [A, s, s];
//! - `ramp:SLOPE[,MAX]` — SLOPE·t clipped at ±MAX [A/s, A];
//! - `csv:FILE` — one column `i_ref_a` (header required), one row per 1 kHz sample, held after the end.
//!
//! What it is not: a controller (no feedback) — closed-loop excitation lives in `frictionless-acquire`.

use std::path::PathBuf;

/// Errors parsing a profile spec or reading its file.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// The spec does not match any form.
    #[error(
        "bad current profile {0:?}: expected const:I, sine:A,F[,I0], step:L,T_ON[,T_OFF], ramp:SLOPE[,MAX] or csv:FILE"
    )]
    BadSpec(String),
    /// The CSV file cannot be read or parsed.
    #[error("current profile file {path}: {why}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

/// A current reference as a function of time [A, robot convention].
#[derive(Clone, Debug, PartialEq)]
pub enum CurrentProfile {
    /// Constant current.
    Const {
        /// Current [A].
        i_a: f64,
    },
    /// i0 + A·sin(2π·f·t).
    Sine {
        /// Amplitude [A].
        amplitude_a: f64,
        /// Frequency [Hz].
        frequency_hz: f64,
        /// Offset [A].
        offset_a: f64,
    },
    /// A step of `level_a` between `t_on_s` and `t_off_s`.
    Step {
        /// Level [A].
        level_a: f64,
        /// Switch-on time [s].
        t_on_s: f64,
        /// Switch-off time [s] (∞ = never).
        t_off_s: f64,
    },
    /// slope·t clipped at ±max.
    Ramp {
        /// Slope [A/s].
        slope_a_per_s: f64,
        /// Clip [A] (∞ = none).
        max_a: f64,
    },
    /// Samples at 1 kHz, held after the end.
    Samples {
        /// i_ref per sample [A].
        i_a: Vec<f64>,
        /// Sample period [s].
        period_s: f64,
    },
}

fn nums(spec: &str, args: &str, min: usize, max: usize) -> Result<Vec<f64>, ProfileError> {
    let v: Result<Vec<f64>, _> = args.split(',').map(|a| a.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if v.len() >= min && v.len() <= max && v.iter().all(|x| x.is_finite()) => Ok(v),
        _ => Err(ProfileError::BadSpec(spec.to_owned())),
    }
}

impl CurrentProfile {
    /// Parses a spec (see the module doc). `period_s` is the sample period for `csv:` files.
    pub fn parse(spec: &str, period_s: f64) -> Result<Self, ProfileError> {
        let (kind, args) = spec
            .split_once(':')
            .ok_or_else(|| ProfileError::BadSpec(spec.to_owned()))?;
        Ok(match kind.trim() {
            "const" => Self::Const {
                i_a: nums(spec, args, 1, 1)?[0],
            },
            "sine" => {
                let v = nums(spec, args, 2, 3)?;
                Self::Sine {
                    amplitude_a: v[0],
                    frequency_hz: v[1],
                    offset_a: v.get(2).copied().unwrap_or(0.0),
                }
            }
            "step" => {
                let v = nums(spec, args, 2, 3)?;
                Self::Step {
                    level_a: v[0],
                    t_on_s: v[1],
                    t_off_s: v.get(2).copied().unwrap_or(f64::INFINITY),
                }
            }
            "ramp" => {
                let v = nums(spec, args, 1, 2)?;
                Self::Ramp {
                    slope_a_per_s: v[0],
                    max_a: v.get(1).copied().unwrap_or(f64::INFINITY).abs(),
                }
            }
            "csv" => Self::from_csv(PathBuf::from(args.trim()), period_s)?,
            _ => return Err(ProfileError::BadSpec(spec.to_owned())),
        })
    }

    fn from_csv(path: PathBuf, period_s: f64) -> Result<Self, ProfileError> {
        let err = |why: String| ProfileError::File {
            path: path.clone(),
            why,
        };
        let (file, _) = frictionless::regular_file::open(&path).map_err(|e| err(e.to_string()))?;
        let mut rd = csv::Reader::from_reader(file);
        let col = rd
            .headers()
            .map_err(|e| err(e.to_string()))?
            .iter()
            .position(|h| h.trim() == "i_ref_a")
            .ok_or_else(|| err("no column named i_ref_a".into()))?;
        let mut i_a = Vec::new();
        for (n, rec) in rd.records().enumerate() {
            let rec = rec.map_err(|e| err(e.to_string()))?;
            let field = rec.get(col).unwrap_or("");
            let v: f64 = field
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| {
                    err(format!(
                        "row {}: i_ref_a {field:?} is not a finite number",
                        n + 2
                    ))
                })?;
            i_a.push(v);
        }
        if i_a.is_empty() {
            return Err(err("no rows".into()));
        }
        Ok(Self::Samples { i_a, period_s })
    }

    /// i_ref at time `t_s` [A].
    pub fn current_a(&self, t_s: f64) -> f64 {
        match *self {
            Self::Const { i_a } => i_a,
            Self::Sine {
                amplitude_a,
                frequency_hz,
                offset_a,
            } => offset_a + amplitude_a * (std::f64::consts::TAU * frequency_hz * t_s).sin(),
            Self::Step {
                level_a,
                t_on_s,
                t_off_s,
            } => {
                if t_s >= t_on_s && t_s < t_off_s {
                    level_a
                } else {
                    0.0
                }
            }
            Self::Ramp {
                slope_a_per_s,
                max_a,
            } => (slope_a_per_s * t_s).clamp(-max_a, max_a),
            Self::Samples { ref i_a, period_s } => {
                let k = (t_s / period_s).round().max(0.0) as usize;
                i_a[k.min(i_a.len() - 1)]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_form_and_rejects_garbage() {
        let s = CurrentProfile::parse("sine:0.5,2,0.1", 1e-3).unwrap();
        assert!((s.current_a(0.125) - 0.6).abs() < 1e-12);
        let st = CurrentProfile::parse("step:1.0,0.5,1.0", 1e-3).unwrap();
        assert_eq!(st.current_a(0.4), 0.0);
        assert_eq!(st.current_a(0.7), 1.0);
        assert_eq!(st.current_a(1.2), 0.0);
        let r = CurrentProfile::parse("ramp:-0.2,0.3", 1e-3).unwrap();
        assert!((r.current_a(1.0) + 0.2).abs() < 1e-12);
        assert_eq!(r.current_a(10.0), -0.3);
        assert!(CurrentProfile::parse("sine:1", 1e-3).is_err());
        assert!(CurrentProfile::parse("wobble:1", 1e-3).is_err());
        assert!(CurrentProfile::parse("const:nan", 1e-3).is_err());
    }
}
