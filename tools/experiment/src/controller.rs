//! The paper's high-level controller: computed-torque position control of one joint.
//!
//! What it **is**: [`ComputedTorque`] evaluates
//! `τ_des = M(s)·(s̈_d + K_d·(ṡ_d − ṡ) + K_p·(s_d − s)) + h(s, ṡ)` with `M = I_L(s)` and
//! `h = c(s, ṡ) + g(s)` from the same link model the virtual plant uses (the preset's `[plant.link]`
//! table through [`frictionless_sim::link::link_from_model`]: the analytic pendulum or the URDF
//! single-joint view of [`frictionless_dynamics::SingleJoint`]), and [`Reference`] gives the desired
//! trajectory (sinusoid or hold).
//!
//! Units of the gains (paper §9, "s̈* = s̈_des + K_d(ṡ_des − ṡ) + K_p(s_des − s)", then τ = M·s̈* + h):
//! the gains act on the *acceleration* set-point, so `K_p` is in 1/s² and `K_d` in 1/s (rad/s² per rad
//! and per rad/s); the torque gains are `M·K_p` [Nm/rad] and `M·K_d` [Nm·s/rad]. K_d = 4 in every
//! experiment of the paper ([`PAPER_KD_PER_S`]).
//!
//! Like the paper's controller, `M` is the URDF link inertia only: the reflected rotor inertia
//! `r²·J_m` of the harmonic drive is not in the URDF, so the loop gain the plant really sees is
//! `K_p·I_L/(I_L + r²J_m)` — which is why the required K_p are large (ankle roll I_L = 0.0054 kg·m²
//! against r²J_m = 0.128 kg·m²).
//!
//! [`ComputedTorque::extra_inertia_kgm2`] adds a constant to M: with the reflected rotor inertia
//! (`frictl experiment --controller-inertia link-rotor`) the controller models the whole inertia the
//! motor accelerates, the loop gain is the K_p asked for, and K_d·(I_L + r²J_m) is 25× more damping on
//! the ankle roll — a diagnostic of how much the paper's numbers owe to M = I_L, not the paper's setup.
//!
//! What it is **not**: no I/O, no low-level torque-to-current law (that is `frictiond`).

use frictionless_sim::link::LinkDynamics;

/// The paper's derivative gain K_d [1/s] (all experiments).
pub const PAPER_KD_PER_S: f64 = 4.0;

/// Desired joint trajectory.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum Reference {
    /// `s_d(t) = centre − A·cos(2π f t)`: starts at rest at `centre − A` (no velocity step) and
    /// oscillates around `centre` with amplitude `A`.
    Sine {
        /// Centre [rad].
        centre_rad: f64,
        /// Amplitude A [rad].
        amplitude_rad: f64,
        /// Frequency f [Hz].
        freq_hz: f64,
    },
    /// Constant position.
    Hold {
        /// Held position [rad].
        s_rad: f64,
    },
}

/// Desired position, velocity and acceleration at one instant.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Setpoint {
    /// s_d [rad].
    pub s_rad: f64,
    /// ṡ_d [rad/s].
    pub sdot_rad_s: f64,
    /// s̈_d [rad/s²].
    pub sddot_rad_s2: f64,
}

impl Reference {
    /// The set-point at time `t_s` [s] after the start.
    pub fn at(&self, t_s: f64) -> Setpoint {
        match *self {
            Reference::Sine {
                centre_rad,
                amplitude_rad,
                freq_hz,
            } => {
                let w = std::f64::consts::TAU * freq_hz;
                let (sn, cs) = (w * t_s).sin_cos();
                Setpoint {
                    s_rad: centre_rad - amplitude_rad * cs,
                    sdot_rad_s: amplitude_rad * w * sn,
                    sddot_rad_s2: amplitude_rad * w * w * cs,
                }
            }
            Reference::Hold { s_rad } => Setpoint {
                s_rad,
                sdot_rad_s: 0.0,
                sddot_rad_s2: 0.0,
            },
        }
    }

    /// Where the trajectory starts (the plant's initial pose for a run).
    pub fn start_rad(&self) -> f64 {
        self.at(0.0).s_rad
    }
}

/// Computed-torque control of one joint (see the module doc).
pub struct ComputedTorque<L: LinkDynamics> {
    /// Link model: M = I_L(s), h = c(s, ṡ) + g(s).
    pub link: L,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// K_d [1/s].
    pub kd_per_s: f64,
    /// Constant inertia added to M [kg·m²] (0 = the paper's M = I_L; r²·J_m models the rotor).
    pub extra_inertia_kgm2: f64,
}

impl<L: LinkDynamics> ComputedTorque<L> {
    /// A controller with the paper's K_d = 4.
    pub fn paper(link: L, kp_per_s2: f64) -> Self {
        Self {
            link,
            kp_per_s2,
            kd_per_s: PAPER_KD_PER_S,
            extra_inertia_kgm2: 0.0,
        }
    }

    /// τ_des [Nm] for measured `s_rad`, `sdot_rad_s` and set-point `sp`.
    #[inline]
    pub fn tau_des_nm(&self, s_rad: f64, sdot_rad_s: f64, sp: &Setpoint) -> f64 {
        let acc = sp.sddot_rad_s2
            + self.kd_per_s * (sp.sdot_rad_s - sdot_rad_s)
            + self.kp_per_s2 * (sp.s_rad - s_rad);
        (self.link.inertia_kgm2(s_rad) + self.extra_inertia_kgm2) * acc
            + self.link.velocity_torque_nm(s_rad, sdot_rad_s)
            + self.link.gravity_nm(s_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless_sim::Pendulum;

    #[test]
    fn sine_reference_derivatives_match_finite_differences() {
        let r = Reference::Sine {
            centre_rad: -0.8,
            amplitude_rad: 0.4,
            freq_hz: 0.2,
        };
        assert!((r.start_rad() - (-1.2)).abs() < 1e-15);
        assert_eq!(r.at(0.0).sdot_rad_s, 0.0);
        let h = 1e-5;
        for t in [0.3, 1.1, 2.7] {
            let (a, b, c) = (r.at(t - h), r.at(t), r.at(t + h));
            let v = (c.s_rad - a.s_rad) / (2.0 * h);
            let acc = (c.s_rad - 2.0 * b.s_rad + a.s_rad) / (h * h);
            assert!((v - b.sdot_rad_s).abs() < 1e-8, "{v} vs {}", b.sdot_rad_s);
            assert!(
                (acc - b.sddot_rad_s2).abs() < 1e-3,
                "{acc} vs {}",
                b.sddot_rad_s2
            );
        }
    }

    #[test]
    fn computed_torque_is_inertia_times_pd_plus_gravity() {
        let link = Pendulum {
            inertia_kgm2: 0.5,
            gravity_amplitude_nm: 10.0,
            gravity_phase_rad: 0.0,
        };
        let c = ComputedTorque::paper(link, 100.0);
        let sp = Setpoint {
            s_rad: 0.1,
            sdot_rad_s: 0.2,
            sddot_rad_s2: 0.3,
        };
        // at the set-point: only feed-forward and gravity
        let on = c.tau_des_nm(0.1, 0.2, &sp);
        assert!((on - (0.5 * 0.3 + 10.0 * 0.1f64.sin())).abs() < 1e-12);
        // a position error of 0.01 rad adds I·Kp·e; a velocity error adds I·Kd·ė
        let off = c.tau_des_nm(0.09, 0.2, &sp);
        let grav_diff = 10.0 * (0.09f64.sin() - 0.1f64.sin());
        assert!((off - on - (0.5 * 100.0 * 0.01 + grav_diff)).abs() < 1e-12);
        let slow = c.tau_des_nm(0.1, 0.0, &sp);
        assert!((slow - on - 0.5 * 4.0 * 0.2).abs() < 1e-12);
        // extra inertia scales the PD and feed-forward part only, not gravity
        let with_rotor = ComputedTorque {
            extra_inertia_kgm2: 0.25,
            ..c
        };
        let off2 = with_rotor.tau_des_nm(0.09, 0.2, &sp);
        let on2 = with_rotor.tau_des_nm(0.1, 0.2, &sp);
        assert!((on2 - (0.75 * 0.3 + 10.0 * 0.1f64.sin())).abs() < 1e-12);
        assert!((off2 - on2 - (0.75 * 100.0 * 0.01 + grav_diff)).abs() < 1e-12);
    }
}
