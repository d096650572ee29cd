//! A joint torque sensor between the gearbox output and the link, and a logger's jittered clock: what a
//! torque-sensed arm reports besides its joint encoder and motor current.
//!
//! What it is: [`TorqueSensor`], which turns a sample's [`Truth`] into the reading of a sensor at the
//! output flange (its parameters, [`TorqueSensorParams`], are the `[plant.torque_sensor]` table of
//! [`crate::params`]: noise, offset, resolution):
//!
//! ```text
//! τ_joint = τ_t − τ_Fj + offset + N(0, σ²), rounded to the resolution        [Nm, joint side]
//! ```
//!
//! τ_t − τ_Fj is the torque the flange passes to the link, I_L(s)·s̈ + c(s, ṡ) + g(s) − τ_ext, positive
//! in the direction of s. With the motor-side torque through the gearbox r_signed·k_t·i (robot
//! convention) the torque-sensor friction label is
//!
//! ```text
//! r_signed·k_t·i − τ_joint = τ_Fm + τ_Fj + J_eq·φ̈ (− offset − noise)
//! ```
//!
//! the true friction plus the reflected rotor inertia term (no link model needed: gravity and the link's
//! inertia are inside τ_joint). [`TorqueSensor::stamp_s`] adds the logger's timestamp jitter (uniform,
//! at most ±`jitter_s`) to a sample time, as a host-side logger of a real arm does.
//!
//! What it is not: part of the plant's equations (the sensor is ideal-stiff, it does not change the
//! dynamics) or a log writer (`frictionless-acquire`).

use crate::params::ParamError;
pub use crate::params::TorqueSensorParams;
use crate::plant::Truth;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// The link-side torque at the output flange, τ_t − τ_Fj [Nm] (what an ideal sensor reads).
pub fn link_side_torque_nm(truth: &Truth) -> f64 {
    truth.tau_t_nm - truth.tau_fj_nm
}

/// A seeded joint torque sensor and logger clock.
#[derive(Clone, Debug)]
pub struct TorqueSensor {
    p: TorqueSensorParams,
    rng: ChaCha8Rng,
}

impl TorqueSensor {
    /// A sensor with its own noise stream from `seed` (independent of the plant's).
    pub fn new(p: TorqueSensorParams, seed: u64) -> Result<Self, ParamError> {
        p.validate()?;
        Ok(Self {
            p,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7a5e_5e50_0000_0001),
        })
    }

    /// The sensor's reading for one sample [Nm] (see the module doc).
    pub fn read_nm(&mut self, truth: &Truth) -> f64 {
        let noise: f64 = self.rng.sample(StandardNormal);
        let v = link_side_torque_nm(truth) + self.p.offset_nm + self.p.noise_std_nm * noise;
        let q = self.p.resolution_nm;
        if q > 0.0 { (v / q).round() * q } else { v }
    }

    /// `time_s` plus a uniform jitter in [−jitter_s, jitter_s] (0: unchanged) [s].
    pub fn stamp_s(&mut self, time_s: f64, jitter_s: f64) -> f64 {
        if jitter_s > 0.0 {
            time_s + self.rng.random_range(-jitter_s..=jitter_s)
        } else {
            time_s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_flange_torque_with_offset_noise_and_resolution() {
        let truth = Truth {
            tau_t_nm: 3.0,
            tau_fj_nm: 0.75,
            ..Truth::default()
        };
        assert_eq!(link_side_torque_nm(&truth), 2.25);
        let ideal = TorqueSensorParams {
            noise_std_nm: 0.0,
            offset_nm: 0.0,
            resolution_nm: 0.0,
        };
        assert_eq!(TorqueSensor::new(ideal, 1).unwrap().read_nm(&truth), 2.25);
        let p = TorqueSensorParams {
            noise_std_nm: 0.1,
            offset_nm: 0.5,
            resolution_nm: 0.01,
        };
        let mut s = TorqueSensor::new(p.clone(), 3).unwrap();
        let n = 20_000;
        let v: Vec<f64> = (0..n).map(|_| s.read_nm(&truth)).collect();
        let mean = v.iter().sum::<f64>() / n as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!((mean - 2.75).abs() < 0.005, "mean {mean}");
        assert!((sd - 0.1).abs() < 0.005, "sd {sd}");
        assert!(
            v.iter()
                .all(|x| ((x / 0.01).round() * 0.01 - x).abs() < 1e-12)
        );
        let mut again = TorqueSensor::new(p, 3).unwrap();
        assert_eq!(again.read_nm(&truth), v[0], "seeded");
        let t: Vec<f64> = (0..1000)
            .map(|k| s.stamp_s(k as f64 * 2e-3, 3e-4))
            .collect();
        assert!(
            t.iter()
                .enumerate()
                .all(|(k, x)| (x - k as f64 * 2e-3).abs() <= 3e-4)
        );
        assert!(t.iter().enumerate().any(|(k, x)| *x != k as f64 * 2e-3));
        let bad = TorqueSensorParams {
            noise_std_nm: -1.0,
            ..TorqueSensorParams::default()
        };
        assert!(TorqueSensor::new(bad, 0).is_err());
    }
}
