//! Dataset output: a CSV log with documented columns and a JSON sidecar.
//!
//! What it is: [`CsvLog`], which writes [`LogRow`]s as CSV (header row, one line per 1 kHz sample,
//! readable by pandas and PlotJuggler), the column documentation [`COLUMNS`] / [`SIM_COLUMNS`], and
//! [`Sidecar`], the JSON metadata next to it (joint, signed r, k_t, seed, plant parameters, protocol,
//! chunk table, guard events, column docs).
//!
//! What it is not: a reader or a label pipeline (that is `frictl preprocess`).

use std::io::Write;

use serde::Serialize;

use crate::acquire::config::ProtocolConfig;
use crate::acquire::protocol::{AcquireError, Block, LogRow, RunSummary};
use crate::sim::params::PlantParams;

/// Documentation of one CSV column.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ColumnDoc {
    /// Header name.
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Meaning.
    pub doc: &'static str,
}

const fn col(name: &'static str, unit: &'static str, doc: &'static str) -> ColumnDoc {
    ColumnDoc { name, unit, doc }
}

/// Columns present in every log (robot and simulator).
pub const COLUMNS: &[ColumnDoc] = &[
    col("time_s", "s", "sample time, 1 kHz"),
    col("chunk", "-", "block id; windows must not cross chunks"),
    col(
        "active",
        "0/1",
        "1 while the block excites the joint; 0 while re-centring or held by a guard",
    ),
    col(
        "mode",
        "code",
        "0 re-centre (position control), 1 current excitation, 2 guard hold, 3 closed-loop tracking",
    ),
    col("s_rad", "rad", "joint encoder, quantised to 2*pi/2^18"),
    col(
        "theta_motor_rad",
        "motor rad",
        "motor encoder theta = r_signed*phi, quantised to 2*pi/3600",
    ),
    col(
        "omega_motor_rad_s",
        "motor rad/s",
        "motor velocity from motor-encoder differences",
    ),
    col(
        "i_ref_a",
        "A",
        "current reference sent after this sample (robot convention: joint torque = r_signed*kt*i)",
    ),
    col(
        "i_meas_a",
        "A",
        "measured motor current (robot convention), 1 mA resolution",
    ),
    col(
        "temperature_c",
        "degC",
        "winding temperature, 0.1 degC resolution; NaN without a sensor",
    ),
];

/// Extra columns of simulated logs: the truth, for diagnostics only (never model inputs).
pub const SIM_COLUMNS: &[ColumnDoc] = &[
    col(
        "tau_f_true_nm",
        "Nm",
        "true joint-side friction tau_Fm + tau_Fj",
    ),
    col(
        "tau_fm_nm",
        "Nm",
        "motor-side friction reflected to the joint",
    ),
    col("tau_fj_nm", "Nm", "output-side LuGre friction"),
    col("tau_t_nm", "Nm", "flexspline torque"),
    col("z", "rad", "LuGre bristle state"),
    col(
        "phi_ddot",
        "rad/s^2",
        "motor acceleration reflected to the joint",
    ),
    col("gravity_nm", "Nm", "gravity torque g(s)"),
    col("s_true_rad", "rad", "true joint angle"),
    col("s_dot_true_rad_s", "rad/s", "true joint velocity"),
];

/// Significant digits kept in the CSV: below every sensor's resolution (an 18-bit encoder over ±π
/// needs 6), and it keeps the file about half the size of full round-trip output.
pub const CSV_SIGNIFICANT_DIGITS: i32 = 9;

/// Rounds to [`CSV_SIGNIFICANT_DIGITS`] significant digits; magnitudes below 1e-30 become 0.
pub fn round_significant(v: f64) -> f64 {
    let a = v.abs();
    if !v.is_finite() || a == 0.0 {
        return v;
    }
    if a < 1e-30 {
        return 0.0;
    }
    let e = a.log10().floor() as i32;
    let p = CSV_SIGNIFICANT_DIGITS - 1 - e;
    if p >= 0 {
        let m = 10f64.powi(p);
        (v * m).round() / m
    } else {
        let m = 10f64.powi(-p);
        (v / m).round() * m
    }
}

/// CSV writer for [`LogRow`]s.
pub struct CsvLog<W: Write> {
    w: csv::Writer<W>,
    with_truth: bool,
    buf: String,
}

impl<W: Write> CsvLog<W> {
    /// Starts a log and writes the header; `with_truth` adds [`SIM_COLUMNS`].
    pub fn new(out: W, with_truth: bool) -> Result<Self, AcquireError> {
        let mut w = csv::WriterBuilder::new().from_writer(out);
        let names = COLUMNS
            .iter()
            .chain(if with_truth { SIM_COLUMNS } else { &[] })
            .map(|c| c.name);
        w.write_record(names)
            .map_err(|e| AcquireError::Sink(e.to_string()))?;
        Ok(Self {
            w,
            with_truth,
            buf: String::with_capacity(32),
        })
    }

    fn field(&mut self, v: f64) -> Result<(), AcquireError> {
        use std::fmt::Write as _;
        self.buf.clear();
        let _ = write!(self.buf, "{}", round_significant(v));
        self.w
            .write_field(self.buf.as_bytes())
            .map_err(|e| AcquireError::Sink(e.to_string()))
    }

    /// Writes one row.
    pub fn write(&mut self, row: &LogRow) -> Result<(), AcquireError> {
        let m = &row.meas;
        self.field(m.time_s)?;
        self.field(f64::from(row.chunk))?;
        self.field(f64::from(u8::from(row.active)))?;
        self.field(f64::from(row.mode as u8))?;
        for v in [
            m.s_rad,
            m.theta_motor_rad,
            m.omega_motor_rad_s,
            row.i_ref_a,
            m.i_meas_a,
            m.temperature_c,
        ] {
            self.field(v)?;
        }
        if self.with_truth {
            let t = row.truth.unwrap_or_default();
            for v in [
                t.tau_f_nm,
                t.tau_fm_nm,
                t.tau_fj_nm,
                t.tau_t_nm,
                t.z_rad,
                t.phi_ddot_rad_s2,
                t.gravity_nm,
                t.state.s_rad,
                t.state.s_dot_rad_s,
            ] {
                self.field(v)?;
            }
        }
        self.w
            .write_record(None::<&[u8]>)
            .map_err(|e| AcquireError::Sink(e.to_string()))
    }

    /// Flushes and returns the inner writer.
    pub fn finish(self) -> Result<W, AcquireError> {
        self.w
            .into_inner()
            .map_err(|e| AcquireError::Sink(e.to_string()))
    }
}

/// [`Sidecar::source`] of logs made offline against the simulator (truth columns present).
pub const SOURCE_OFFLINE_SIM: &str = "offline-sim";
/// [`Sidecar::source`] of logs made live against a plant over shared memory (no truth columns:
/// the process only sees what a robot would report).
pub const SOURCE_LIVE_SHM: &str = "live-shm";

/// Connection facts of a live acquisition (sidecar field `live`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LiveInfo {
    /// iceoryx2 service prefix.
    pub prefix: String,
    /// iceoryx2 root path (`None` = iceoryx2's default).
    pub root_path: Option<String>,
    /// Payload index of the acquired joint.
    pub joint_index: usize,
    /// `seq` of the first state used (time 0 of the log).
    pub first_seq: u64,
    /// States received.
    pub states_received: u64,
    /// States skipped (gaps in `seq`): samples the plant stepped without a fresh command from us.
    pub states_skipped: u64,
    /// Whether a `SimTruth` publisher was connected (the plant is a simulator); its truth is not
    /// logged.
    pub plant_publishes_sim_truth: bool,
}

/// The JSON sidecar written next to a log.
#[derive(Clone, Debug, Serialize)]
pub struct Sidecar<'a> {
    /// Format tag.
    pub format: &'static str,
    /// Producer (`frictl <version>`).
    pub producer: String,
    /// Joint name.
    pub joint: &'a str,
    /// Signed gear ratio (robot convention).
    pub gear_ratio_signed: f64,
    /// Torque constant used for commands [Nm/A].
    pub kt_nm_per_a: f64,
    /// Control/log period [s].
    pub sample_period_s: f64,
    /// Whether the log comes from the offline simulator (then the truth columns are present).
    pub simulated: bool,
    /// Where the samples came from: [`SOURCE_OFFLINE_SIM`] or [`SOURCE_LIVE_SHM`].
    pub source: &'static str,
    /// Live runs: the connection and what was received.
    pub live: Option<LiveInfo>,
    /// RNG seed of the simulator.
    pub seed: Option<u64>,
    /// Initial winding temperature drawn from the seed [°C].
    pub initial_temperature_c: Option<f64>,
    /// The preset name or file.
    pub preset: &'a str,
    /// Full plant parameters: the simulator's (offline runs) or, for live runs, the preset whose
    /// nominal values (signed r, k_t, J_eq, link, i_max) the protocol's controllers used.
    pub plant: Option<&'a PlantParams>,
    /// Full protocol configuration.
    pub protocol: &'a ProtocolConfig,
    /// The CSV file name.
    pub csv: &'a str,
    /// Column documentation, in file order.
    pub columns: Vec<ColumnDoc>,
    /// The chunk table.
    pub chunks: &'a [Block],
    /// Run summary (samples, guard events).
    pub summary: &'a RunSummary,
}

/// The columns of a log with or without the truth.
pub fn columns(with_truth: bool) -> Vec<ColumnDoc> {
    COLUMNS
        .iter()
        .chain(if with_truth { SIM_COLUMNS } else { &[] })
        .copied()
        .collect()
}
