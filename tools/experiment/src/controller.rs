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

/// Computed-torque control of a whole multi-joint chain (the virtual leg) with its full rigid-body
/// model: `τ_des = M(q)·(q̈_d + K_d·(q̇_d − q̇) + K_p·(q_d − q)) + h(q, q̇)`, with M and h of the
/// nominal URDF ([`frictionless_sim::LegParams::nominal_robot`]), evaluated as one recursive
/// Newton–Euler pass `rnea(q, q̇, q̈*)` (which is exactly `M(q)·q̈* + h(q, q̇)`), plus an optional
/// constant diagonal inertia per joint (the reflected rotor inertia r²·J_m, off in the paper's setup).
///
/// Joints are in *payload* order (joint k of the leg parameters = payload index k); the robot's own
/// joint order may differ, [`LegComputedTorque::new`] maps between them. `K_p` is per joint [1/s²],
/// `K_d` shared [1/s]. Allocation-free after construction.
pub struct LegComputedTorque {
    robot: frictionless_dynamics::Robot,
    ws: frictionless_dynamics::Workspace,
    /// `order[k]`: robot index of payload joint k.
    order: Vec<usize>,
    q: Vec<f64>,
    qd: Vec<f64>,
    acc: Vec<f64>,
    tau: Vec<f64>,
    /// K_p per payload joint [1/s²].
    pub kp_per_s2: Vec<f64>,
    /// K_d [1/s].
    pub kd_per_s: f64,
    /// Constant inertia added to M's diagonal per payload joint [kg·m²] (0 = the paper's M).
    pub extra_inertia_kgm2: Vec<f64>,
}

impl LegComputedTorque {
    /// A controller for `robot` whose payload joint k is the robot joint named `names[k]`, with the
    /// paper's K_d = 4 and gains `kp_per_s2` (one per name).
    pub fn new(
        robot: frictionless_dynamics::Robot,
        names: &[&str],
        kp_per_s2: Vec<f64>,
    ) -> Result<Self, frictionless_dynamics::DynamicsError> {
        let n = robot.dof();
        let order = names
            .iter()
            .map(|nm| robot.joint_index(nm))
            .collect::<Result<Vec<_>, _>>()?;
        if names.len() != n || kp_per_s2.len() != n {
            return Err(frictionless_dynamics::DynamicsError::Dimension {
                what: "leg controller joints and gains",
                expected: n,
                got: names.len().min(kp_per_s2.len()),
            });
        }
        Ok(Self {
            ws: frictionless_dynamics::Workspace::new(&robot),
            robot,
            order,
            q: vec![0.0; n],
            qd: vec![0.0; n],
            acc: vec![0.0; n],
            tau: vec![0.0; n],
            kp_per_s2,
            kd_per_s: PAPER_KD_PER_S,
            extra_inertia_kgm2: vec![0.0; n],
        })
    }

    /// Joints of the chain.
    pub fn dof(&self) -> usize {
        self.order.len()
    }

    /// τ_des [Nm] per payload joint into `out`, for measured `s_rad`, `sdot_rad_s` and set-points
    /// `sp` (all in payload order, one per joint).
    pub fn tau_des_nm(
        &mut self,
        s_rad: &[f64],
        sdot_rad_s: &[f64],
        sp: &[Setpoint],
        out: &mut [f64],
    ) -> Result<(), frictionless_dynamics::DynamicsError> {
        let n = self.dof();
        for (what, got) in [
            ("s_rad", s_rad.len()),
            ("sdot_rad_s", sdot_rad_s.len()),
            ("set-points", sp.len()),
            ("tau_des_nm", out.len()),
        ] {
            if got != n {
                return Err(frictionless_dynamics::DynamicsError::Dimension {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        for k in 0..n {
            let r = self.order[k];
            self.q[r] = s_rad[k];
            self.qd[r] = sdot_rad_s[k];
            self.acc[r] = sp[k].sddot_rad_s2
                + self.kd_per_s * (sp[k].sdot_rad_s - sdot_rad_s[k])
                + self.kp_per_s2[k] * (sp[k].s_rad - s_rad[k]);
        }
        self.robot
            .rnea(&mut self.ws, &self.q, &self.qd, &self.acc, &mut self.tau)?;
        for ((o, &r), extra) in out
            .iter_mut()
            .zip(&self.order)
            .zip(&self.extra_inertia_kgm2)
        {
            *o = self.tau[r] + extra * self.acc[r];
        }
        Ok(())
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
    #[test]
    fn leg_computed_torque_is_full_mass_matrix_times_pd_plus_bias() {
        use frictionless_sim::LegParams;
        let leg = LegParams::preset().unwrap();
        let robot = leg.nominal_robot().unwrap();
        let names: Vec<&str> = leg.joints.iter().map(|p| p.joint.as_str()).collect();
        let n = names.len();
        // payload order reversed against the robot's, to exercise the mapping
        let rev: Vec<&str> = names.iter().rev().copied().collect();
        let kp: Vec<f64> = (0..n).map(|k| 50.0 + 30.0 * k as f64).collect();
        let mut c = LegComputedTorque::new(robot.clone(), &rev, kp.clone()).unwrap();
        c.extra_inertia_kgm2[1] = 0.3;
        let s: Vec<f64> = (0..n).map(|k| 0.1 * k as f64 - 0.2).collect();
        let sd: Vec<f64> = (0..n).map(|k| 0.3 - 0.1 * k as f64).collect();
        let sp: Vec<Setpoint> = (0..n)
            .map(|k| Setpoint {
                s_rad: s[k] + 0.01 * (k as f64 + 1.0),
                sdot_rad_s: 0.05 * k as f64,
                sddot_rad_s2: 1.0 - 0.3 * k as f64,
            })
            .collect();
        let mut out = vec![0.0; n];
        c.tau_des_nm(&s, &sd, &sp, &mut out).unwrap();
        // the same in robot order through M(q) and h(q, q̇)
        let mut ws = frictionless_dynamics::Workspace::new(&robot);
        let idx: Vec<usize> = rev
            .iter()
            .map(|nm| robot.joint_index(nm).unwrap())
            .collect();
        let (mut q, mut qd, mut acc) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for k in 0..n {
            q[idx[k]] = s[k];
            qd[idx[k]] = sd[k];
            acc[idx[k]] = sp[k].sddot_rad_s2
                + PAPER_KD_PER_S * (sp[k].sdot_rad_s - sd[k])
                + kp[k] * (sp[k].s_rad - s[k]);
        }
        let mut m = nalgebra::DMatrix::zeros(n, n);
        robot.mass_matrix(&mut ws, &q, &mut m).unwrap();
        let mut h = vec![0.0; n];
        robot.bias_torques(&mut ws, &q, &qd, &mut h).unwrap();
        let tau = m * nalgebra::DVector::from_column_slice(&acc);
        for k in 0..n {
            let r = idx[k];
            let want = tau[r] + h[r] + if k == 1 { 0.3 * acc[r] } else { 0.0 };
            assert!(
                (out[k] - want).abs() < 1e-9 * (1.0 + want.abs()),
                "joint {}: {} vs {want}",
                rev[k],
                out[k]
            );
        }
        // the coupling is real: a position error on one joint moves the others' torques
        let mut sp2 = sp.clone();
        sp2[0].s_rad += 0.1;
        let mut out2 = vec![0.0; n];
        c.tau_des_nm(&s, &sd, &sp2, &mut out2).unwrap();
        assert!((1..n).any(|k| (out2[k] - out[k]).abs() > 1e-6));
        // wrong lengths are an error, not a panic
        assert!(c.tau_des_nm(&s[..2], &sd, &sp, &mut out).is_err());
    }
}
