//! The two-inertia harmonic-drive joint: equations, 20 kHz integration, 1 kHz sensor emulation.
//!
//! What it is: [`Plant`], exactly reference §2/§4/§5 — current-loop lag, motor + wave-generator inertia
//! J_eq = r²J_m, nonlinear flexspline k1·Δ + k3·Δ³ + d_t·(φ̇ − ṡ) with an optional smoothed dead-zone,
//! motor-side Coulomb + viscous friction, output-side LuGre with Stribeck, direction-dependent Coulomb
//! ±ΔF_c, load-dependent μ·|τ_t|, friction ripple (e1, e2), a thermal ODE with β_v/β_c, link inertia and
//! gravity from a [`LinkDynamics`], and an external torque input. Semi-implicit Euler on (φ̇, φ, ṡ, s)
//! with the exact exponential LuGre update; the current reference is held for one 1 kHz sample; sensors
//! (encoders, noisy current, temperature) are emulated on the sampled outputs only. The true friction
//! and its parts are returned as diagnostics ([`Truth`]). Deterministic for a seed (ChaCha8).
//!
//! Conventions: the state is joint side with |r| (φ = θ/r is the motor angle reflected to the joint,
//! positive in the joint's direction). The *commanded and measured current is in the robot's
//! convention*: joint torque = r_signed·k_t·i, and θ_meas = r_signed·φ.
//!
//! What it is not: a controller, a protocol or a plant server (see `frictionless-acquire`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::link::LinkDynamics;
use crate::params::{MotorEncoderKind, ParamError, PlantParams};
use crate::stribeck::StribeckTable;
use frictionless::fastmath;

/// Continuous state of the joint (joint side, |r|).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantState {
    /// Simulated time [s].
    pub time_s: f64,
    /// Joint angle s [rad].
    pub s_rad: f64,
    /// Joint velocity ṡ [rad/s].
    pub s_dot_rad_s: f64,
    /// Motor angle reflected to the joint φ = θ/r [rad].
    pub phi_rad: f64,
    /// φ̇ [rad/s].
    pub phi_dot_rad_s: f64,
    /// LuGre bristle deflection z [rad].
    pub z_rad: f64,
    /// Actual motor current (robot convention, after the current-loop lag) [A].
    pub i_a: f64,
    /// Winding temperature T [°C].
    pub temperature_c: f64,
}

/// True internal quantities over the last physics step of a sample (diagnostics, never model inputs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    /// True joint-side friction τ_F = τ_Fm + τ_Fj [Nm].
    pub tau_f_nm: f64,
    /// Motor-side friction reflected to the joint τ_Fm [Nm].
    pub tau_fm_nm: f64,
    /// Output-side (LuGre) friction τ_Fj [Nm].
    pub tau_fj_nm: f64,
    /// Flexspline torque τ_t [Nm].
    pub tau_t_nm: f64,
    /// LuGre bristle state z [rad].
    pub z_rad: f64,
    /// Motor acceleration reflected to the joint φ̈ [rad/s²].
    pub phi_ddot_rad_s2: f64,
    /// Joint acceleration s̈ [rad/s²].
    pub s_ddot_rad_s2: f64,
    /// Gravity torque g(s) [Nm].
    pub gravity_nm: f64,
    /// Steady-state LuGre level g_ss [Nm].
    pub g_ss_nm: f64,
    /// The continuous state at the sample instant.
    pub state: PlantState,
}

/// What the robot's sensors report at a 1 kHz sample (robot conventions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Sample time [s].
    pub time_s: f64,
    /// Joint encoder, quantised to 2π/counts [rad].
    pub s_rad: f64,
    /// Motor encoder θ = r_signed·φ, quantised to 2π/counts [motor rad].
    pub theta_motor_rad: f64,
    /// Motor velocity from motor-encoder differences [motor rad/s].
    pub omega_motor_rad_s: f64,
    /// Measured motor current (robot convention) with noise, rounded to the resolution [A].
    pub i_meas_a: f64,
    /// Winding temperature rounded to the resolution [°C] (NaN without a sensor).
    pub temperature_c: f64,
}

/// One 1 kHz output: the measurement and the truth behind it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Emulated sensors.
    pub meas: Measurement,
    /// Diagnostics.
    pub truth: Truth,
}

/// Quantises `x` to the nearest multiple of `q`.
#[inline]
fn quantise(x: f64, q: f64) -> f64 {
    if q > 0.0 { (x / q).round() * q } else { x }
}

/// (sin d, cos d) for |d| ≤ 0.1 from the Taylor series to d⁹ and d¹⁰ (truncation below 3e-19).
#[inline(always)]
fn sin_cos_small(d: f64) -> (f64, f64) {
    let d2 = d * d;
    // Horner forms of d − d³/3! + … + d⁹/9! and 1 − d²/2! + … − d¹⁰/10!
    let sd = d
        * (1.0
            + d2 * (-1.0 / 6.0
                + d2 * (1.0 / 120.0 + d2 * (-1.0 / 5040.0 + d2 * (1.0 / 362_880.0)))));
    let cd = 1.0
        + d2 * (-0.5
            + d2 * (1.0 / 24.0
                + d2 * (-1.0 / 720.0 + d2 * (1.0 / 40_320.0 + d2 * (-1.0 / 3_628_800.0)))));
    (sd, cd)
}

/// Rotates (sin a, cos a) to (sin(a + d), cos(a + d)). For |d| < 0.1 with Taylor series of sin d and
/// cos d (truncation below 3e-19 — far under one ulp; three terms fewer for |d| < 1e-3); for |d| < 0.8 from d/8 and three angle
/// doublings (sin 2h = 2·sin h·cos h, cos 2h = 1 − 2·sin²h, ≈ 1 ulp each); else by evaluating
/// `new_angle` directly. Replaces two libm calls per physics step by a dozen multiply-adds (the
/// motor ripple angle 2|r|φ advances by up to 0.8 rad per step at |φ̇| ≈ 50 rad/s on the ankle); the
/// rounding drift over the ≤ 20 steps of a sample (re-synchronised every sample) is a few ulp.
#[inline(always)]
pub(crate) fn rotate(sin_a: &mut f64, cos_a: &mut f64, d: f64, new_angle: f64) {
    let a = d.abs();
    let (sd, cd) = if a < 1e-3 {
        // the joint angle's step (|ṡ|·dt < 1e-3 below 20 rad/s): to d⁵ and d⁶ (truncation < 2e-25)
        let d2 = d * d;
        let sd = d * d2.mul_add(d2.mul_add(1.0 / 120.0, -1.0 / 6.0), 1.0);
        let cd = d2.mul_add(d2.mul_add(d2.mul_add(-1.0 / 720.0, 1.0 / 24.0), -0.5), 1.0);
        (sd, cd)
    } else if a < 0.1 {
        sin_cos_small(d)
    } else if a < 0.8 {
        let (mut sh, mut ch) = sin_cos_small(d * 0.125);
        for _ in 0..3 {
            (sh, ch) = (2.0 * sh * ch, (-2.0 * sh).mul_add(sh, 1.0));
        }
        (sh, ch)
    } else {
        (*sin_a, *cos_a) = new_angle.sin_cos();
        return;
    };
    let (s, c) = (*sin_a, *cos_a);
    *sin_a = s * cd + c * sd;
    *cos_a = c * cd - s * sd;
}

/// The virtual harmonic-drive joint.
pub struct Plant<L: LinkDynamics = Box<dyn LinkDynamics>> {
    p: PlantParams,
    link: L,
    st: PlantState,
    rng: ChaCha8Rng,
    // derived constants
    r_signed: f64,
    r_abs: f64,
    j_eq: f64,
    dt: f64,
    current_gain: f64,
    c_th: f64,
    // encoders, motor-velocity window, current and temperature sensors
    sensors: Sensors,
    samples: u64,
    last_meas: Measurement,
    last_truth: Truth,
    /// cos p2, sin p2 of the output ripple phase (fast path: sin(s + p2) from sin s, cos s).
    cos_p2: f64,
    sin_p2: f64,
    /// true: every physics step calls libm and the link (the reference); false: the fast path.
    reference_math: bool,
    /// exp(−u^δ) by table for the fast path when δ ≠ 1 (`None`: δ = 1 or δ too small to tabulate).
    stribeck: Option<StribeckTable>,
}

/// Temperature-dependent coefficients, evaluated once per 1 kHz sample: T changes by well under
/// 1 mK per millisecond (τ_th = 300 s), and the exp() per physics step would cost ~10 % of run time.
#[derive(Clone, Copy)]
pub(crate) struct ThermalCoeffs {
    pub(crate) f_c0: f64,
    pub(crate) delta_f_c: f64,
    pub(crate) f_s: f64,
    pub(crate) sigma2m: f64,
    pub(crate) sigma2j: f64,
}

/// Per-drive constants of the friction forces of one physics step (reciprocals and products: the
/// step is one long dependency chain, so a division on it costs its full latency).
#[derive(Clone, Copy, Debug)]
pub(crate) struct FrictionConsts {
    inv_eps_m: f64,
    inv_v_s: f64,
    sigma1_per_dt0: f64,
    inv_sigma0: f64,
    sigma0_dt: f64,
    cos_p2: f64,
    sin_p2: f64,
    dt: f64,
}

impl FrictionConsts {
    /// The constants of `p` at physics step `dt` [s].
    pub(crate) fn new(p: &PlantParams, dt: f64) -> Self {
        Self {
            inv_eps_m: 1.0 / p.eps_m_rad_s,
            inv_v_s: 1.0 / p.v_s_rad_s,
            sigma1_per_dt0: p.sigma1_nms_per_rad / dt,
            inv_sigma0: 1.0 / p.sigma0_nm_per_rad,
            sigma0_dt: p.sigma0_nm_per_rad * dt,
            cos_p2: p.p2_rad.cos(),
            sin_p2: p.p2_rad.sin(),
            dt,
        }
    }

    /// The friction of one drive at the start of a physics step, the fast path's expressions shared
    /// by [`Plant`] and the leg's drives: motor-side τ_Fm, the LuGre level g_ss (Stribeck, thermal
    /// coefficients `tc`, ripple from `sin_m` = sin(2|r|φ + p1) and (sin s, cos s), load term), the
    /// exact exponential bristle update z → z_new for frozen ṡ and the output-side τ_Fj.
    /// Returns (τ_Fm, τ_Fj, z_new, g_ss).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn forces(
        &self,
        p: &PlantParams,
        tc: &ThermalCoeffs,
        stribeck: Option<&StribeckTable>,
        sd: f64,
        phid: f64,
        z: f64,
        tau_t: f64,
        sin_m: f64,
        (sin_s, cos_s): (f64, f64),
    ) -> (f64, f64, f64, f64) {
        let dt = self.dt;
        // motor-side friction (joint side)
        let tau_fm = p.f_cm_nm * fastmath::tanh(phid * self.inv_eps_m) + tc.sigma2m * phid;
        // output-side LuGre level g_ss (same expression as `g_ss_with`)
        let dfc = tc.delta_f_c * fastmath::tanh(sd * 1e3);
        let x = sd.abs() * self.inv_v_s;
        // exp(−x^δ) < 4.3e-18 once x^δ > 40: the Stribeck term is then dropped (error below
        // 4.3e-18·(F_s − F_c) Nm, far under one ulp of g_ss), which skips ln and exp at speed
        let strib = if p.stribeck_exponent == 1.0 {
            if x < 40.0 {
                fastmath::exp_in_range(-x)
            } else {
                0.0
            }
        } else if let Some(table) = stribeck {
            // one load + a cubic instead of ln → exp → exp (≤ 1e-12 absolute, see `stribeck`)
            table.shape(x)
        } else {
            let xd = fastmath::powf(x, p.stribeck_exponent);
            if xd < 40.0 {
                fastmath::exp_in_range(-xd)
            } else {
                0.0
            }
        };
        let mut ripple = 1.0;
        if p.e1 != 0.0 {
            ripple += p.e1 * sin_m;
        }
        if p.e2 != 0.0 {
            // sin(s + p2)
            ripple += p.e2 * (sin_s * self.cos_p2 + cos_s * self.sin_p2);
        }
        // fc + (f_s − fc)·strib with fc = f_c0 + dfc
        let f_s_minus_c0 = tc.f_s - tc.f_c0;
        let level = (f_s_minus_c0 - dfc).mul_add(strib, tc.f_c0 + dfc);
        let g_ss = level.mul_add(ripple, p.mu_load * tau_t.abs());
        // exact exponential LuGre update for frozen ṡ
        let a_dt = self.sigma0_dt * sd.abs() / g_ss;
        let z_new = if a_dt < 1e-12 {
            z + sd * dt
        } else {
            let z_ss = (g_ss * self.inv_sigma0).copysign(sd);
            (z - z_ss).mul_add(fastmath::exp(-a_dt), z_ss)
        };
        let sv2 = x * x;
        // exp(−40) = 4e-18: below that the damping term is far under one ulp of τ_Fj
        let sigma1_per_dt = if sv2 < 40.0 {
            self.sigma1_per_dt0 * fastmath::exp_in_range(-sv2)
        } else {
            0.0
        };
        // σ0·z + σ1·ż + σ2j·ṡ with ż = (z_new − z)/dt, grouped so that z_new → τ_Fj is two FMAs
        let tau_fj = sigma1_per_dt.mul_add(
            z_new - z,
            p.sigma0_nm_per_rad.mul_add(z_new, tc.sigma2j * sd),
        );
        (tau_fm, tau_fj, z_new, g_ss)
    }
}

impl ThermalCoeffs {
    /// The coefficients of `p` at winding temperature `temperature_c` [°C].
    pub(crate) fn at(p: &PlantParams, temperature_c: f64) -> Self {
        let dt = temperature_c - 25.0;
        let c = 1.0 - p.beta_c_per_k * dt;
        let v = (-p.beta_v_per_k * dt).exp();
        ThermalCoeffs {
            f_c0: p.f_c0_nm * c,
            delta_f_c: p.delta_f_c_nm * c,
            f_s: p.f_s0_nm * c,
            sigma2m: p.sigma2m_nms_per_rad * v,
            sigma2j: p.sigma2j_nms_per_rad * v,
        }
    }
}

/// Flexspline elastic torque (no damping) of `p` for a deflection Δ = φ − s [Nm].
#[inline]
pub(crate) fn spring_nm(p: &PlantParams, delta_rad: f64) -> f64 {
    let d = dead_zone(p, delta_rad);
    d * (p.k1_nm_per_rad + p.k3_nm_per_rad3 * d * d)
}

/// Smoothed lost-motion dead-zone of `p`; the identity when `lost_motion_rad` is 0.
#[inline]
fn dead_zone(p: &PlantParams, x: f64) -> f64 {
    let b = p.lost_motion_rad;
    if b == 0.0 {
        return x;
    }
    let e2 = p.lost_motion_smoothing_rad * p.lost_motion_smoothing_rad;
    let a = x - b;
    let c = x + b;
    0.5 * (a + (a * a + e2).sqrt()) + 0.5 * (c - (c * c + e2).sqrt())
}

/// The deflection Δ with spring_nm(Δ) = `tau_nm` (bisection on the monotone spring law, dead-zone
/// included): the wind-up that holds `tau_nm` at rest.
pub(crate) fn spring_deflection_rad(p: &PlantParams, tau_nm: f64) -> f64 {
    let (mut lo, mut hi) = (-1.0_f64, 1.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if spring_nm(p, mid) < tau_nm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The emulated sensors of one joint: encoders, motor-velocity window, noisy current, temperature.
#[derive(Clone, Debug)]
pub(crate) struct Sensors {
    /// Quantised θ of the last N + 1 samples (ring).
    theta_hist: Vec<f64>,
    theta_pos: usize,
    /// What the motor encoder read at power-up and subtracts ever since (0 for an absolute one)
    /// [motor rad].
    theta_zero_rad: f64,
}

impl Sensors {
    pub(crate) fn new(p: &PlantParams) -> Self {
        Self {
            theta_hist: vec![0.0; p.sensors.motor_velocity_window_samples as usize + 1],
            theta_pos: 0,
            theta_zero_rad: 0.0,
        }
    }

    /// Motor encoder θ = r_signed·φ quantised [motor rad].
    pub(crate) fn theta_quantised(p: &PlantParams, st: &PlantState) -> f64 {
        let q = std::f64::consts::TAU / f64::from(p.sensors.motor_encoder_counts_per_rev);
        quantise(p.gear_ratio_signed * st.phi_rad, q)
    }

    /// A power-up at rest: an incremental motor encoder takes the current θ as its zero; fills the
    /// motor-velocity window with the θ it reads.
    pub(crate) fn reset(&mut self, p: &PlantParams, st: &PlantState) {
        let raw = Self::theta_quantised(p, st);
        self.theta_zero_rad = match p.sensors.motor_encoder {
            MotorEncoderKind::Absolute => 0.0,
            MotorEncoderKind::Incremental => raw,
        };
        let theta_q = raw - self.theta_zero_rad;
        self.theta_hist.iter_mut().for_each(|t| *t = theta_q);
    }

    /// One sample of every sensor at `time_s` (draws the current noise from `rng`).
    pub(crate) fn measure(
        &mut self,
        p: &PlantParams,
        st: &PlantState,
        rng: &mut ChaCha8Rng,
        time_s: f64,
    ) -> Measurement {
        let sens = &p.sensors;
        let q_s = std::f64::consts::TAU / f64::from(sens.joint_encoder_counts_per_rev);
        let theta = Self::theta_quantised(p, st) - self.theta_zero_rad;
        // ring of the last N+1 quantised motor angles
        let n = self.theta_hist.len();
        self.theta_pos = (self.theta_pos + 1) % n;
        self.theta_hist[self.theta_pos] = theta;
        let oldest = self.theta_hist[(self.theta_pos + 1) % n];
        let window_s = (n - 1) as f64 * p.sample_period_s();
        let noise: f64 = rng.sample(StandardNormal);
        let i_meas = quantise(
            st.i_a + sens.current_noise_std_a * noise,
            sens.current_resolution_a,
        );
        Measurement {
            time_s,
            s_rad: quantise(st.s_rad, q_s),
            theta_motor_rad: theta,
            omega_motor_rad_s: (theta - oldest) / window_s,
            i_meas_a: i_meas,
            temperature_c: if sens.temperature_sensor {
                quantise(st.temperature_c, sens.temperature_resolution_c)
            } else {
                f64::NAN
            },
        }
    }
}

impl<L: LinkDynamics> Plant<L> {
    /// A plant at rest at `params.initial_s_rad`, pre-wound to hold gravity, with T₀ drawn from the seed.
    pub fn new(params: PlantParams, link: L, seed: u64) -> Result<Self, ParamError> {
        params.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let t0 = if params.t0_max_c > params.t0_min_c {
            rng.random_range(params.t0_min_c..params.t0_max_c)
        } else {
            params.t0_min_c
        };
        let r_signed = params.gear_ratio_signed;
        let dt = params.dt_physics_s;
        let mut plant = Self {
            r_abs: r_signed.abs(),
            j_eq: params.j_eq_kgm2(),
            current_gain: 1.0 - (-dt / params.tau_current_s).exp(),
            c_th: params.tau_th_s / params.r_th_k_per_w,
            r_signed,
            dt,
            link,
            rng,
            st: PlantState {
                time_s: 0.0,
                s_rad: 0.0,
                s_dot_rad_s: 0.0,
                phi_rad: 0.0,
                phi_dot_rad_s: 0.0,
                z_rad: 0.0,
                i_a: 0.0,
                temperature_c: t0,
            },
            sensors: Sensors::new(&params),
            samples: 0,
            last_meas: Measurement {
                time_s: 0.0,
                s_rad: 0.0,
                theta_motor_rad: 0.0,
                omega_motor_rad_s: 0.0,
                i_meas_a: 0.0,
                temperature_c: f64::NAN,
            },
            last_truth: Truth::default(),
            cos_p2: params.p2_rad.cos(),
            sin_p2: params.p2_rad.sin(),
            reference_math: false,
            stribeck: if params.stribeck_exponent == 1.0 {
                None
            } else {
                StribeckTable::new(params.stribeck_exponent)
            },
            p: params,
        };
        plant.reset_at_rest(plant.p.initial_s_rad);
        Ok(plant)
    }

    /// Puts the joint at rest at `s0_rad`: ṡ = φ̇ = 0, the flexspline wound to hold gravity
    /// (φ = s₀ + Δ with k1·Δ + k3·Δ³ = g(s₀)), z = 0, current at the holding value; keeps T and time.
    pub fn reset_at_rest(&mut self, s0_rad: f64) {
        let g = self.link.gravity_nm(s0_rad);
        // Bisection on the monotone spring law (dead-zone included): robust for any parameters.
        let delta = spring_deflection_rad(&self.p, g);
        self.st.s_rad = s0_rad;
        self.st.s_dot_rad_s = 0.0;
        self.st.phi_rad = s0_rad + delta;
        self.st.phi_dot_rad_s = 0.0;
        self.st.z_rad = 0.0;
        self.st.i_a = g / (self.r_signed * self.p.kt_nm_per_a);
        self.sensors.reset(&self.p, &self.st);
        self.last_truth = Truth {
            gravity_nm: g,
            tau_t_nm: g,
            state: self.st,
            ..Truth::default()
        };
        self.last_meas = self.measure(0.0);
    }

    /// Selects the integration path. `false` (the default) is the fast path: per 1 kHz sample the
    /// link's [`closed_form`](LinkDynamics::closed_form) is read once and sin/cos of the joint angle and
    /// of the motor ripple angle are evaluated once, then advanced through the physics steps by exact
    /// rotation (Taylor sin/cos of the per-step angle increment, with angle doubling up to 0.8 rad,
    /// recomputed directly beyond); `exp` and `tanh` are the inlined [`fastmath`] kernels (≤ 1–2 ulp
    /// from libm, bounds in that module); for δ ≠ 1 the Stribeck shape exp(−|ṡ/v_s|^δ) comes from
    /// the plant's [`StribeckTable`] (≤ 1e-12 absolute from libm; `powf` + `exp` only in the stick
    /// phase |ṡ| < v_s·2⁻²⁰); the Stribeck term is 0 once |ṡ/v_s|^δ ≥ 40 (below
    /// 4.3e-18·(F_s − F_c)) and the σ1·exp(−(ṡ/v_s)²) factor is 0 where it is below 4e-18·σ1;
    /// sums on the step's dependency
    /// chain are regrouped into FMAs. `true` runs the reference: libm and the link every physics
    /// step, exactly the equations as written. The two agree to rounding and the table's 1e-12
    /// (over 120 s of stick-slip the joint angles differ by ≤ 2e-10 rad on the ankle, ≈ 1e-15 rad on
    /// the knee, far below the encoder's 2.4e-5 rad, see `tools/sim/tests/sim_physics.rs`, which asserts ≤ 1e-6 rad). Both are
    /// deterministic for a seed.
    pub fn set_reference_math(&mut self, reference: bool) {
        self.reference_math = reference;
    }

    /// Whether the reference path (libm every physics step) is selected.
    pub fn reference_math(&self) -> bool {
        self.reference_math
    }

    /// The parameters.
    pub fn params(&self) -> &PlantParams {
        &self.p
    }

    /// The link dynamics.
    pub fn link(&self) -> &L {
        &self.link
    }

    /// The continuous state.
    pub fn state(&self) -> PlantState {
        self.st
    }

    /// Overwrites the continuous state (tests, scenario setup). Sensors are not re-sampled; the
    /// sample clock keeps counting from where it was.
    pub fn set_state(&mut self, st: PlantState) {
        self.st = PlantState {
            time_s: self.st.time_s,
            ..st
        };
    }

    /// The most recent measurement (the initial one before the first [`Plant::step`]).
    pub fn measurement(&self) -> Measurement {
        self.last_meas
    }

    /// The most recent truth.
    pub fn truth(&self) -> Truth {
        self.last_truth
    }

    /// Flexspline elastic torque (no damping) for a deflection Δ = φ − s [Nm].
    #[inline]
    fn spring_nm(&self, delta_rad: f64) -> f64 {
        spring_nm(&self.p, delta_rad)
    }

    fn thermal_coeffs(&self) -> ThermalCoeffs {
        ThermalCoeffs::at(&self.p, self.st.temperature_c)
    }

    /// Steady-state LuGre level g_ss(ṡ) [Nm] at the current position and flexspline torque.
    pub fn g_ss_nm(&self, s_dot_rad_s: f64, tau_t_nm: f64) -> f64 {
        self.g_ss_with(&self.thermal_coeffs(), s_dot_rad_s, tau_t_nm)
    }

    #[inline(always)]
    fn g_ss_with(&self, tc: &ThermalCoeffs, s_dot: f64, tau_t: f64) -> f64 {
        let p = &self.p;
        let av = s_dot.abs();
        let fc = tc.f_c0 + tc.delta_f_c * (s_dot * 1e3).tanh();
        let x = av / p.v_s_rad_s;
        let strib = if p.stribeck_exponent == 1.0 {
            (-x).exp()
        } else {
            (-x.powf(p.stribeck_exponent)).exp()
        };
        let mut ripple = 1.0;
        if p.e1 != 0.0 {
            ripple += p.e1 * (2.0 * self.r_abs * self.st.phi_rad + p.p1_rad).sin();
        }
        if p.e2 != 0.0 {
            ripple += p.e2 * (self.st.s_rad + p.p2_rad).sin();
        }
        (fc + (tc.f_s - fc) * strib) * ripple + p.mu_load * tau_t.abs()
    }

    /// Advances one control sample (`substeps_per_sample` physics steps) holding `i_ref_a`
    /// (robot convention, saturated at ±i_max) and an external joint torque `tau_ext_nm`.
    pub fn step(&mut self, i_ref_a: f64, tau_ext_nm: f64) -> Sample {
        let i_ref = if i_ref_a.is_nan() {
            0.0
        } else {
            i_ref_a.clamp(-self.p.i_max_a, self.p.i_max_a)
        };
        let tc = self.thermal_coeffs();
        let mut truth = if self.reference_math {
            let mut truth = Truth::default();
            for _ in 0..self.p.substeps_per_sample {
                truth = self.substep(&tc, i_ref, tau_ext_nm);
            }
            truth
        } else {
            self.substeps_fast(&tc, i_ref, tau_ext_nm)
        };
        // Time as sample count × period: no drift from summing dt.
        self.samples += 1;
        self.st.time_s = self.samples as f64 * self.p.sample_period_s();
        truth.state = self.st;
        self.last_truth = truth;
        self.last_meas = self.measure(self.st.time_s);
        Sample {
            meas: self.last_meas,
            truth,
        }
    }

    #[inline(always)]
    fn substep(&mut self, tc: &ThermalCoeffs, i_ref: f64, tau_ext: f64) -> Truth {
        let p = &self.p;
        let dt = self.dt;
        let PlantState {
            s_rad: s,
            s_dot_rad_s: sd,
            phi_rad: phi,
            phi_dot_rad_s: phid,
            z_rad: z,
            i_a: i,
            ..
        } = self.st;

        // flexspline
        let tau_t = self.spring_nm(phi - s) + p.d_t_nms_per_rad * (phid - sd);
        // motor-side friction (joint side)
        let tau_fm = p.f_cm_nm * (phid / p.eps_m_rad_s).tanh() + tc.sigma2m * phid;
        // output-side LuGre, exact exponential update for frozen ṡ
        let g_ss = self.g_ss_with(tc, sd, tau_t);
        let a_dt = p.sigma0_nm_per_rad * sd.abs() / g_ss * dt;
        let z_new = if a_dt < 1e-12 {
            z + sd * dt
        } else {
            let z_ss = (g_ss / p.sigma0_nm_per_rad).copysign(sd);
            z_ss + (z - z_ss) * (-a_dt).exp()
        };
        let z_dot = (z_new - z) / dt;
        let sv = sd / p.v_s_rad_s;
        let sigma1 = p.sigma1_nms_per_rad * (-sv * sv).exp();
        let tau_fj = p.sigma0_nm_per_rad * z_new + sigma1 * z_dot + tc.sigma2j * sd;
        // link
        let g = self.link.gravity_nm(s);
        let il = self.link.inertia_kgm2(s);
        let c = self.link.velocity_torque_nm(s, sd);
        let s_dd = (tau_t - tau_fj - g - c + tau_ext) / il;
        let phi_dd = (self.r_signed * p.kt_nm_per_a * i - tau_t - tau_fm) / self.j_eq;
        // semi-implicit Euler: velocities first, then positions with the new velocities
        let phid_new = phid + phi_dd * dt;
        let sd_new = sd + s_dd * dt;
        let heat_w = p.r_w_ohm * i * i + (tau_fm * phid).abs() + (tau_fj * sd).abs()
            - (self.st.temperature_c - p.t_amb_c) / p.r_th_k_per_w;
        self.st.phi_dot_rad_s = phid_new;
        self.st.s_dot_rad_s = sd_new;
        self.st.phi_rad = phi + phid_new * dt;
        self.st.s_rad = s + sd_new * dt;
        self.st.z_rad = z_new;
        self.st.temperature_c += dt * heat_w / self.c_th;
        // current loop: exact first-order lag with the held reference
        self.st.i_a = i + (i_ref - i) * self.current_gain;
        self.st.time_s += dt;
        Truth {
            tau_f_nm: tau_fm + tau_fj,
            tau_fm_nm: tau_fm,
            tau_fj_nm: tau_fj,
            tau_t_nm: tau_t,
            z_rad: z_new,
            phi_ddot_rad_s2: phi_dd,
            s_ddot_rad_s2: s_dd,
            gravity_nm: g,
            g_ss_nm: g_ss,
            state: self.st,
        }
    }

    /// The fast path of [`Plant::step`]: `substeps_per_sample` physics steps with the state in
    /// registers, no link call and no `sin` per step when the link has a closed form, and the
    /// inlined [`fastmath`] kernels instead of libm (see [`Plant::set_reference_math`] for what
    /// differs from [`Plant::substep`]).
    #[inline(never)]
    fn substeps_fast(&mut self, tc: &ThermalCoeffs, i_ref: f64, tau_ext: f64) -> Truth {
        // One monomorphised loop per link kind: the closed-form link needs no call and no branch.
        let (st, truth) = match self.link.closed_form() {
            Some(cf) => {
                let inv_il = 1.0 / cf.inertia_kgm2;
                self.substeps_fast_with(tc, i_ref, tau_ext, |_s, _sd, sin_s, cos_s| {
                    (
                        cf.gravity_sin_nm * sin_s + cf.gravity_cos_nm * cos_s,
                        inv_il,
                        0.0,
                    )
                })
            }
            None => {
                let link = &self.link;
                self.substeps_fast_with(tc, i_ref, tau_ext, |s, sd, _sin_s, _cos_s| {
                    (
                        link.gravity_nm(s),
                        1.0 / link.inertia_kgm2(s),
                        link.velocity_torque_nm(s, sd),
                    )
                })
            }
        };
        self.st = st;
        truth
    }

    /// The loop of [`Plant::substeps_fast`]; `link(s, ṡ, sin s, cos s)` returns
    /// (g(s) [Nm], 1/I_L(s) [1/(kg·m²)], c(s, ṡ) [Nm]).
    #[inline(always)]
    fn substeps_fast_with(
        &self,
        tc: &ThermalCoeffs,
        i_ref: f64,
        tau_ext: f64,
        link: impl Fn(f64, f64, f64, f64) -> (f64, f64, f64),
    ) -> (PlantState, Truth) {
        let p = &self.p;
        let dt = self.dt;
        let mut st = self.st;
        let two_r = 2.0 * self.r_abs;
        let ripple_m = p.e1 != 0.0;
        let (mut sin_s, mut cos_s) = st.s_rad.sin_cos();
        let (mut sin_m, mut cos_m) = if ripple_m {
            (two_r * st.phi_rad + p.p1_rad).sin_cos()
        } else {
            (0.0, 1.0)
        };
        let drive_nm_per_a = self.r_signed * p.kt_nm_per_a;
        // Reciprocals: the step is one long dependency chain (ṡ → g_ss → exp → z → τ_Fj → s̈ → ṡ),
        // so every division on it costs its full latency; a multiply costs a quarter of that.
        let inv_j_eq = 1.0 / self.j_eq;
        let dt_per_c_th = dt / self.c_th;
        let inv_r_th = 1.0 / p.r_th_k_per_w;
        let fk = FrictionConsts {
            cos_p2: self.cos_p2,
            sin_p2: self.sin_p2,
            ..FrictionConsts::new(p, dt)
        };
        let stribeck_table = self.stribeck.as_ref();
        let n = p.substeps_per_sample;
        let mut truth = Truth::default();
        for k in 0..n {
            let PlantState {
                s_rad: s,
                s_dot_rad_s: sd,
                phi_rad: phi,
                phi_dot_rad_s: phid,
                z_rad: z,
                i_a: i,
                ..
            } = st;
            // flexspline
            let tau_t = self.spring_nm(phi - s) + p.d_t_nms_per_rad * (phid - sd);
            // motor-side friction, LuGre level, bristles, output-side friction
            let (tau_fm, tau_fj, z_new, g_ss) = fk.forces(
                p,
                tc,
                stribeck_table,
                sd,
                phid,
                z,
                tau_t,
                sin_m,
                (sin_s, cos_s),
            );
            // link
            let (g, inv_il, c) = link(s, sd, sin_s, cos_s);
            // everything but τ_Fj first: it is ready long before τ_Fj (the end of the chain)
            let tau_rest = tau_t - g - c + tau_ext;
            let phi_dd = (drive_nm_per_a * i - tau_t - tau_fm) * inv_j_eq;
            // semi-implicit Euler: velocities first, then positions with the new velocities
            let phid_new = phid + phi_dd * dt;
            let sd_new = (tau_rest - tau_fj).mul_add(inv_il * dt, sd);
            let heat_w = p.r_w_ohm * i * i + (tau_fm * phid).abs() + (tau_fj * sd).abs()
                - (st.temperature_c - p.t_amb_c) * inv_r_th;
            st.phi_dot_rad_s = phid_new;
            st.s_dot_rad_s = sd_new;
            st.phi_rad = phi + phid_new * dt;
            st.s_rad = s + sd_new * dt;
            st.z_rad = z_new;
            st.temperature_c += heat_w * dt_per_c_th;
            // current loop: exact first-order lag with the held reference
            st.i_a = i + (i_ref - i) * self.current_gain;
            st.time_s += dt;
            if k + 1 == n {
                // the truth of the sample is that of its last physics step
                truth = Truth {
                    tau_f_nm: tau_fm + tau_fj,
                    tau_fm_nm: tau_fm,
                    tau_fj_nm: tau_fj,
                    tau_t_nm: tau_t,
                    z_rad: z_new,
                    phi_ddot_rad_s2: phi_dd,
                    s_ddot_rad_s2: (tau_rest - tau_fj) * inv_il,
                    gravity_nm: g,
                    g_ss_nm: g_ss,
                    state: st,
                };
                break;
            }
            // advance sin/cos of the angles to the new positions
            rotate(&mut sin_s, &mut cos_s, st.s_rad - s, st.s_rad);
            if ripple_m {
                rotate(
                    &mut sin_m,
                    &mut cos_m,
                    two_r * (st.phi_rad - phi),
                    two_r * st.phi_rad + p.p1_rad,
                );
            }
        }
        (st, truth)
    }

    fn measure(&mut self, time_s: f64) -> Measurement {
        self.sensors
            .measure(&self.p, &self.st, &mut self.rng, time_s)
    }

    /// Stored energy [J]: kinetic (½J_eq·φ̇² + ½I_L·ṡ²), flexspline elastic (½k1·Δ² + ¼k3·Δ⁴) and
    /// LuGre bristle (½σ0·z²). Excludes the gravity potential; exact only with `lost_motion_rad` = 0.
    pub fn stored_energy_j(&self) -> f64 {
        let st = &self.st;
        let d = st.phi_rad - st.s_rad;
        0.5 * self.j_eq * st.phi_dot_rad_s * st.phi_dot_rad_s
            + 0.5 * self.link.inertia_kgm2(st.s_rad) * st.s_dot_rad_s * st.s_dot_rad_s
            + 0.5 * self.p.k1_nm_per_rad * d * d
            + 0.25 * self.p.k3_nm_per_rad3 * d * d * d * d
            + 0.5 * self.p.sigma0_nm_per_rad * st.z_rad * st.z_rad
    }
}

impl Plant<Box<dyn LinkDynamics>> {
    /// A plant whose link comes from the parameters' `[plant.link]` table.
    pub fn from_params(params: PlantParams, seed: u64) -> Result<Self, ParamError> {
        let link = crate::link::link_from_model(&params.link)?;
        Self::new(params, link, seed)
    }
}
