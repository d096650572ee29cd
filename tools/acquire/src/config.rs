//! The excitation-protocol configuration (the `[protocol]` table of a preset).
//!
//! What it is: [`ProtocolConfig`] with every number of reference §6.1/§6.2 (starting poses, re-centring,
//! guards, sines, ramps, steps, closed-loop tracking sets), deserialised with unknown keys refused, and
//! validated.
//!
//! What it is not: the schedule or the controller ([`crate::protocol`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use frictionless_sim::params::{ParamError, check};

/// Where the offset current i₀ of the open-loop blocks comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldingCurrent {
    /// i₀ = g(s)/(r_signed·k_t) at the measured position when the block starts.
    Gravity,
    /// i₀ = 0.
    Zero,
}

/// Current sinusoids: for each amplitude (low → high), each frequency (as listed, high → low),
/// `cycles` full periods of i₀ + A·sin(2πft), each its own block.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SineConfig {
    /// Whether the sine blocks run.
    pub enabled: bool,
    /// First amplitude [A] (before `current_scale`).
    pub amplitude_from_a: f64,
    /// Last amplitude, inclusive [A].
    pub amplitude_to_a: f64,
    /// Amplitude increment [A].
    pub amplitude_step_a: f64,
    /// Frequencies in the order played [Hz].
    pub frequencies_hz: Vec<f64>,
    /// Full periods per frequency.
    pub cycles: f64,
}

impl SineConfig {
    /// The amplitudes from `amplitude_from_a` to `amplitude_to_a` inclusive (unscaled) [A].
    pub fn amplitudes_a(&self) -> Vec<f64> {
        let mut out = Vec::new();
        let mut k = 0u32;
        loop {
            let a = self.amplitude_from_a + f64::from(k) * self.amplitude_step_a;
            if a > self.amplitude_to_a + 1e-9 || k > 10_000 {
                break;
            }
            out.push(a);
            k += 1;
        }
        out
    }
}

/// Current ramps i₀ ± slope·t until |Δi| = `max_increment_a`, both directions per slope.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RampConfig {
    /// Whether the ramp blocks run.
    pub enabled: bool,
    /// Slopes [A/s] (before `current_scale`).
    pub slopes_a_per_s: Vec<f64>,
    /// Final increment [A] (before `current_scale`).
    pub max_increment_a: f64,
}

/// Current steps: `hold_s` at i₀ + L, then `rest_s` at i₀.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepConfig {
    /// Whether the step blocks run.
    pub enabled: bool,
    /// Levels L [A] (before `current_scale`), signed.
    pub levels_a: Vec<f64>,
    /// Time at i₀ + L [s].
    pub hold_s: f64,
    /// Time back at i₀ [s].
    pub rest_s: f64,
}

/// A closed-loop sine-tracking set (no friction compensation): s_d = c + A·sin(2πft) where c is the
/// position the re-centring to `centre_rad` actually reached (no error step at the start),
/// s̈_cmd = K_p·(s_d − s) − 2√K_p·ṡ, i_ref = s̈_cmd·(I_L + J_eq)/(r·k_t) + g(s)/(r·k_t).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackingConfig {
    /// Whether this set runs.
    pub enabled: bool,
    /// Centre c [rad].
    pub centre_rad: f64,
    /// Amplitudes A [rad].
    pub amplitudes_rad: Vec<f64>,
    /// Frequencies f [Hz].
    pub frequencies_hz: Vec<f64>,
    /// Proportional gain K_p [1/s²] (acceleration units).
    pub kp_per_s2: f64,
    /// Periods per (A, f) block.
    pub cycles: f64,
}

/// The whole protocol (reference §6.2 defaults per joint in the presets).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProtocolConfig {
    /// Lower software limit [rad].
    pub range_lo_rad: f64,
    /// Upper software limit [rad].
    pub range_hi_rad: f64,
    /// Number of starting poses (inner nodes of the shrunk range split into n + 1 segments).
    pub n_starts: u32,
    /// Shrink of the range on each side before placing the starts [°].
    pub start_shrink_deg: f64,
    /// Offset current of the open-loop blocks.
    pub holding_current: HoldingCurrent,
    /// Multiplies every open-loop current amplitude, slope and step level.
    pub current_scale: f64,
    /// |i_meas| at or above this latches a position hold until the next block [A].
    pub max_safety_current_a: f64,
    /// Distance to a range limit that latches a position hold [°].
    pub limit_margin_deg: f64,
    /// Position-controlled re-centring before every block [s].
    pub recentre_s: f64,
    /// Position controller K_p [1/s²].
    pub position_kp_per_s2: f64,
    /// Position controller K_d [1/s].
    pub position_kd_per_s: f64,
    /// Cut-off of the controller's first-order velocity filter [Hz].
    pub velocity_filter_hz: f64,
    /// Current sinusoids.
    pub sines: SineConfig,
    /// Current ramps.
    pub ramps: RampConfig,
    /// Current steps.
    pub steps: StepConfig,
    /// Closed-loop tracking sets by name (e.g. `train`, `test`).
    #[serde(default)]
    pub tracking: BTreeMap<String, TrackingConfig>,
}

/// `--set` overrides that turn a preset's protocol into its unseen test run: the closed-loop tracking
/// test set only (no sines, ramps, steps or training tracking). `frictl demo` and `frictl robot run`
/// record their held-out runs with them.
pub const UNSEEN_TEST_RUN: [&str; 5] = [
    "protocol.sines.enabled=false",
    "protocol.ramps.enabled=false",
    "protocol.steps.enabled=false",
    "protocol.tracking.train.enabled=false",
    "protocol.tracking.test.enabled=true",
];

impl ProtocolConfig {
    /// Parses the `[protocol]` table of a merged parameter table and validates it.
    pub fn from_table(table: &toml::Table) -> Result<Self, ParamError> {
        let t = table
            .get("protocol")
            .and_then(|v| v.as_table())
            .ok_or(ParamError::MissingTable("protocol"))?;
        let c: ProtocolConfig =
            t.clone()
                .try_into()
                .map_err(|e: toml::de::Error| ParamError::Deserialize {
                    table: "protocol",
                    source: Box::new(e),
                })?;
        c.validate()?;
        Ok(c)
    }

    /// The starting poses [rad]: inner nodes of [lo + shrink, hi − shrink] split into n + 1 segments.
    pub fn starts_rad(&self) -> Vec<f64> {
        let shrink = self.start_shrink_deg.to_radians();
        let lo = self.range_lo_rad + shrink;
        let hi = self.range_hi_rad - shrink;
        let n = self.n_starts;
        (1..=n)
            .map(|k| lo + (hi - lo) * f64::from(k) / f64::from(n + 1))
            .collect()
    }

    /// Checks ranges and signs of every value.
    pub fn validate(&self) -> Result<(), ParamError> {
        let pos = "must be > 0";
        check(
            "protocol.range_hi_rad",
            self.range_hi_rad,
            self.range_lo_rad.is_finite() && self.range_hi_rad > self.range_lo_rad,
            "must be above a finite range_lo_rad",
        )?;
        let shrunk =
            self.range_hi_rad - self.range_lo_rad - 2.0 * self.start_shrink_deg.to_radians();
        check(
            "protocol.start_shrink_deg",
            self.start_shrink_deg,
            self.start_shrink_deg >= 0.0 && shrunk > 0.0,
            "must be >= 0 and leave a non-empty range",
        )?;
        check(
            "protocol.n_starts",
            f64::from(self.n_starts),
            self.n_starts >= 1,
            "must be >= 1",
        )?;
        for (k, v) in [
            ("protocol.current_scale", self.current_scale),
            ("protocol.max_safety_current_a", self.max_safety_current_a),
            ("protocol.position_kp_per_s2", self.position_kp_per_s2),
            ("protocol.velocity_filter_hz", self.velocity_filter_hz),
            (
                "protocol.sines.amplitude_step_a",
                self.sines.amplitude_step_a,
            ),
            ("protocol.sines.cycles", self.sines.cycles),
            ("protocol.ramps.max_increment_a", self.ramps.max_increment_a),
            ("protocol.steps.hold_s", self.steps.hold_s),
        ] {
            check(k, v, v > 0.0, pos)?;
        }
        for (k, v) in [
            ("protocol.limit_margin_deg", self.limit_margin_deg),
            ("protocol.recentre_s", self.recentre_s),
            ("protocol.position_kd_per_s", self.position_kd_per_s),
            ("protocol.steps.rest_s", self.steps.rest_s),
            (
                "protocol.sines.amplitude_from_a",
                self.sines.amplitude_from_a,
            ),
        ] {
            check(k, v, v >= 0.0, "must be >= 0")?;
        }
        check(
            "protocol.sines.amplitude_to_a",
            self.sines.amplitude_to_a,
            self.sines.amplitude_to_a >= self.sines.amplitude_from_a,
            "must be >= amplitude_from_a",
        )?;
        for &f in &self.sines.frequencies_hz {
            check("protocol.sines.frequencies_hz", f, f > 0.0, pos)?;
        }
        for &s in &self.ramps.slopes_a_per_s {
            check("protocol.ramps.slopes_a_per_s", s, s > 0.0, pos)?;
        }
        for &l in &self.steps.levels_a {
            check("protocol.steps.levels_a", l, true, "must be finite")?;
        }
        for t in self.tracking.values() {
            check(
                "protocol.tracking.*.kp_per_s2",
                t.kp_per_s2,
                t.kp_per_s2 > 0.0,
                pos,
            )?;
            check("protocol.tracking.*.cycles", t.cycles, t.cycles > 0.0, pos)?;
            check(
                "protocol.tracking.*.centre_rad",
                t.centre_rad,
                true,
                "must be finite",
            )?;
            for &f in &t.frequencies_hz {
                check("protocol.tracking.*.frequencies_hz", f, f > 0.0, pos)?;
            }
            for &a in &t.amplitudes_rad {
                check(
                    "protocol.tracking.*.amplitudes_rad",
                    a,
                    true,
                    "must be finite",
                )?;
            }
        }
        Ok(())
    }
}
