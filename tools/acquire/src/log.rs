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

use frictionless_dataset::ColumnDoc;

use crate::config::ProtocolConfig;
use crate::protocol::{AcquireError, Block, LogRow, RunSummary};
use frictionless_sim::params::PlantParams;

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

/// 10^k, k = 0..=38, each the correctly rounded f64 of the literal.
#[rustfmt::skip]
const POW10: [f64; 39] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22, 1e23, 1e24, 1e25, 1e26, 1e27, 1e28, 1e29, 1e30, 1e31, 1e32,
    1e33, 1e34, 1e35, 1e36, 1e37, 1e38,
];

/// 10^k as f64 for |k| ≤ 38 (10^−k as the correctly rounded literal's reciprocal is within 1 ulp).
#[inline]
fn pow10(k: i32) -> f64 {
    if k >= 0 {
        POW10[k as usize]
    } else {
        1.0 / POW10[(-k) as usize]
    }
}

/// Rounds to [`CSV_SIGNIFICANT_DIGITS`] significant digits; magnitudes below 1e-30 become 0.
///
/// The decimal exponent comes from the binary one and a table of powers of ten (no `log10`, no
/// `powi`: together they were ≈ 4 % of `frictl acquire`); magnitudes of 1e30 and above, which no
/// logged quantity reaches, take the `log10`/`powi` route.
pub fn round_significant(v: f64) -> f64 {
    let a = v.abs();
    if !v.is_finite() || a == 0.0 {
        return v;
    }
    if a < 1e-30 {
        return 0.0;
    }
    if a >= 1e30 {
        let e = a.log10().floor() as i32;
        let m = 10f64.powi(e - (CSV_SIGNIFICANT_DIGITS - 1));
        return (v / m).round() * m;
    }
    // ⌊log10 a⌋ from the binary exponent (a ≥ 1e-30 is a normal number): within one of the truth,
    // then corrected against the table
    let e2 = ((a.to_bits() >> 52) & 0x7ff) as i32 - 1023;
    let mut e = (f64::from(e2) * std::f64::consts::LOG10_2).floor() as i32;
    if a >= pow10(e + 1) {
        e += 1;
    } else if a < pow10(e) {
        e -= 1;
    }
    let p = CSV_SIGNIFICANT_DIGITS - 1 - e;
    if p >= 0 {
        let m = pow10(p);
        (v * m).round() / m
    } else {
        let m = pow10(-p);
        (v / m).round() * m
    }
}

/// Bytes buffered inside [`CsvLog`] before they are handed to the writer: 1 MiB, at least the
/// `BufWriter` capacity `frictl acquire` and `frictl sim run` use, so that a `BufWriter` passes the
/// chunk straight to the file instead of copying it (the copy was ≈ 5 % of `frictl acquire`).
const CSV_CHUNK_BYTES: usize = 1 << 20;

/// CSV writer for [`LogRow`]s.
///
/// Every field is a number, so no field needs quoting: rows are formatted straight into a byte
/// buffer — floats rounded by [`round_significant`] and printed by `zmij` (shortest round-trip
/// digits of the rounded value: at most [`CSV_SIGNIFICANT_DIGITS`]; plain decimal for magnitudes in
/// [1e-5, 1e16), exponent form such as `2.6805965e-6` outside, `NaN`/`inf`/`-inf` for non-finite
/// values), the integer columns `chunk`, `active`, `mode` by `itoa`. `std::fmt` float formatting was
/// ≈ 45 % of `frictl acquire` time. Lines end in `\n`; the header is the column names.
pub struct CsvLog<W: Write> {
    /// `None` only after [`CsvLog::finish`].
    out: Option<W>,
    with_truth: bool,
    buf: Vec<u8>,
    float: zmij::Buffer,
    int: itoa::Buffer,
}

impl<W: Write> CsvLog<W> {
    /// Starts a log and writes the header; `with_truth` adds [`SIM_COLUMNS`].
    pub fn new(out: W, with_truth: bool) -> Result<Self, AcquireError> {
        let mut log = Self {
            out: Some(out),
            with_truth,
            buf: Vec::with_capacity(CSV_CHUNK_BYTES + 1024),
            float: zmij::Buffer::new(),
            int: itoa::Buffer::new(),
        };
        for (k, c) in COLUMNS
            .iter()
            .chain(if with_truth { SIM_COLUMNS } else { &[] })
            .enumerate()
        {
            if k > 0 {
                log.buf.push(b',');
            }
            log.buf.extend_from_slice(c.name.as_bytes());
        }
        log.buf.push(b'\n');
        Ok(log)
    }

    #[inline]
    fn float(&mut self, v: f64) {
        self.buf.push(b',');
        let text = self.float.format(round_significant(v));
        self.buf.extend_from_slice(text.as_bytes());
    }

    #[inline]
    fn int(&mut self, v: u32) {
        self.buf.push(b',');
        self.buf.extend_from_slice(self.int.format(v).as_bytes());
    }

    /// Hands the buffered bytes to the writer.
    fn drain(&mut self) -> Result<(), AcquireError> {
        if let Some(out) = self.out.as_mut() {
            out.write_all(&self.buf)
                .map_err(|e| AcquireError::Sink(e.to_string()))?;
        }
        self.buf.clear();
        Ok(())
    }

    /// Writes one row.
    pub fn write(&mut self, row: &LogRow) -> Result<(), AcquireError> {
        let m = &row.meas;
        // time first, without the leading comma the helpers add
        let text = self.float.format(round_significant(m.time_s));
        self.buf.extend_from_slice(text.as_bytes());
        self.int(row.chunk);
        self.int(u32::from(row.active));
        self.int(u32::from(row.mode as u8));
        for v in [
            m.s_rad,
            m.theta_motor_rad,
            m.omega_motor_rad_s,
            row.i_ref_a,
            m.i_meas_a,
            m.temperature_c,
        ] {
            self.float(v);
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
                self.float(v);
            }
        }
        self.buf.push(b'\n');
        if self.buf.len() >= CSV_CHUNK_BYTES {
            self.drain()?;
        }
        Ok(())
    }

    /// Flushes and returns the inner writer.
    pub fn finish(mut self) -> Result<W, AcquireError> {
        self.drain()?;
        let mut out = self
            .out
            .take()
            .ok_or_else(|| AcquireError::Sink("CSV log already finished".to_owned()))?;
        out.flush().map_err(|e| AcquireError::Sink(e.to_string()))?;
        Ok(out)
    }
}

impl<W: Write> Drop for CsvLog<W> {
    /// Best effort: a log dropped without [`CsvLog::finish`] (an error path) still gets its
    /// buffered rows, as the `csv` crate's writer did.
    fn drop(&mut self) {
        if self.out.is_some() {
            let _ = self.drain();
            if let Some(out) = self.out.as_mut() {
                let _ = out.flush();
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Mode;
    use frictionless_sim::{Measurement, PlantState, Truth};

    /// The written precision: |parsed − v| may be half a unit in the 9th significant digit (plus
    /// rounding of the scaling), and magnitudes below 1e-30 are written as 0.
    fn assert_round_trips(v: f64, parsed: f64, what: &str) {
        if v.is_nan() {
            assert!(parsed.is_nan(), "{what}: NaN written as {parsed}");
            return;
        }
        if v.is_infinite() || v == 0.0 {
            assert_eq!(parsed, v, "{what}");
            return;
        }
        if v.abs() < 1e-30 {
            assert_eq!(parsed, 0.0, "{what}: {v:e} below 1e-30");
            return;
        }
        let e = v.abs().log10().floor();
        // half a unit of the 9th digit; the digit boundary may sit one decade off right at a power
        // of ten, so allow the coarser of the two
        let half_unit = 0.5 * 10f64.powf(e + 1.0 - f64::from(CSV_SIGNIFICANT_DIGITS));
        assert!(
            (parsed - v).abs() <= half_unit * (1.0 + 1e-9),
            "{what}: {v:e} came back as {parsed:e} (allowed ±{half_unit:e})"
        );
    }

    fn row(values: &[f64; 15], chunk: u32, active: bool, mode: Mode) -> LogRow {
        LogRow {
            chunk,
            active,
            mode,
            meas: Measurement {
                time_s: values[0],
                s_rad: values[1],
                theta_motor_rad: values[2],
                omega_motor_rad_s: values[3],
                i_meas_a: values[4],
                temperature_c: values[5],
            },
            i_ref_a: values[6],
            truth: Some(Truth {
                tau_f_nm: values[7],
                tau_fm_nm: values[8],
                tau_fj_nm: values[9],
                tau_t_nm: values[10],
                z_rad: values[11],
                phi_ddot_rad_s2: values[12],
                gravity_nm: values[13],
                state: PlantState {
                    s_rad: values[14],
                    s_dot_rad_s: -values[14] * 3.7,
                    ..PlantState::default()
                },
                ..Truth::default()
            }),
        }
    }

    /// Values over every magnitude the logs can hold, both signs, the special values, and numbers
    /// that sit on rounding boundaries of the 9th digit.
    fn test_values() -> Vec<f64> {
        let mut v = vec![
            0.0,
            -0.0,
            1.0,
            31.0,
            0.001,
            1e-5,
            -1e-5,
            9.9999999995e-5,
            0.123456789,
            0.1234567895,
            -2.6805965e-6,
            123_456_789.0,
            1_234_567_891.0,
            1e-31,
            -3e-35,
            7.5e29,
            2.0e31,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // a deterministic quasi-random sweep over 1e-32..1e32 (golden-ratio sequence)
        let mut u = 0.5f64;
        for k in 0..30_000 {
            u = (u + 0.618_033_988_749_894_9) % 1.0;
            let mag = 10f64.powf(-32.0 + 64.0 * u);
            v.push(if k % 2 == 0 { mag } else { -mag });
        }
        v
    }

    #[test]
    fn csv_round_trips_every_value_to_the_written_precision() {
        let values = test_values();
        let mut log = CsvLog::new(Vec::new(), true).unwrap();
        let mut rows = Vec::new();
        for (k, chunk) in values.chunks(15).enumerate() {
            let mut fields = [0.0; 15];
            fields[..chunk.len()].copy_from_slice(chunk);
            let modes = [Mode::Recentre, Mode::Current, Mode::Hold, Mode::Tracking];
            let r = row(&fields, k as u32 * 7919, k % 3 == 0, modes[k % 4]);
            log.write(&r).unwrap();
            rows.push(r);
        }
        let bytes = log.finish().unwrap();
        let mut rd = csv::ReaderBuilder::new()
            .has_headers(true)
            .from_reader(bytes.as_slice());
        let header: Vec<String> = rd.headers().unwrap().iter().map(str::to_owned).collect();
        let want: Vec<&str> = columns(true).iter().map(|c| c.name).collect();
        assert_eq!(header, want, "header is the documented column list");
        let mut n = 0;
        for (rec, r) in rd.records().zip(&rows) {
            let rec = rec.unwrap();
            assert_eq!(rec.len(), want.len());
            // integer columns are written as integers
            assert_eq!(rec[1].parse::<u32>().unwrap(), r.chunk);
            assert_eq!(rec[2].parse::<u8>().unwrap(), u8::from(r.active));
            assert_eq!(rec[3].parse::<u8>().unwrap(), r.mode as u8);
            let t = r.truth.unwrap();
            let m = &r.meas;
            let expect = [
                (0, m.time_s),
                (4, m.s_rad),
                (5, m.theta_motor_rad),
                (6, m.omega_motor_rad_s),
                (7, r.i_ref_a),
                (8, m.i_meas_a),
                (9, m.temperature_c),
                (10, t.tau_f_nm),
                (11, t.tau_fm_nm),
                (12, t.tau_fj_nm),
                (13, t.tau_t_nm),
                (14, t.z_rad),
                (15, t.phi_ddot_rad_s2),
                (16, t.gravity_nm),
                (17, t.state.s_rad),
                (18, t.state.s_dot_rad_s),
            ];
            for (col, v) in expect {
                let parsed: f64 = rec[col]
                    .parse()
                    .unwrap_or_else(|e| panic!("column {col} {:?}: {e}", &rec[col]));
                assert_round_trips(v, parsed, want[col]);
            }
            n += 1;
        }
        assert_eq!(n, rows.len(), "one line per row");
    }

    #[test]
    fn csv_without_truth_has_only_the_robot_columns() {
        let mut log = CsvLog::new(Vec::new(), false).unwrap();
        let mut r = row(&[0.25; 15], 3, true, Mode::Current);
        r.truth = None;
        r.meas.temperature_c = f64::NAN;
        log.write(&r).unwrap();
        let text = String::from_utf8(log.finish().unwrap()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2);
        let names: Vec<&str> = COLUMNS.iter().map(|c| c.name).collect();
        assert_eq!(lines[0], names.join(","));
        let fields: Vec<&str> = lines[1].split(',').collect();
        assert_eq!(fields.len(), COLUMNS.len());
        assert_eq!(&fields[1..4], &["3", "1", "1"]);
        assert!(fields[9].parse::<f64>().unwrap().is_nan());
        assert_eq!(fields[4].parse::<f64>().unwrap(), 0.25);
    }

    #[test]
    fn a_dropped_log_still_writes_its_rows() {
        let mut out = Vec::new();
        {
            let mut log = CsvLog::new(&mut out, false).unwrap();
            log.write(&row(&[1.5; 15], 0, false, Mode::Hold)).unwrap();
        }
        assert_eq!(String::from_utf8(out).unwrap().lines().count(), 2);
    }

    /// The table-driven [`round_significant`] against the direct log10/powi formula.
    #[test]
    fn round_significant_matches_the_log10_formula() {
        for v in test_values() {
            let direct = {
                let a = v.abs();
                if !v.is_finite() || a == 0.0 {
                    v
                } else if a < 1e-30 {
                    0.0
                } else {
                    let e = a.log10().floor() as i32;
                    let m = 10f64.powi(e - (CSV_SIGNIFICANT_DIGITS - 1));
                    (v / m).round() * m
                }
            };
            let fast = round_significant(v);
            if !v.is_finite() {
                assert!(fast == v || (fast.is_nan() && v.is_nan()), "{v}: {fast}");
                continue;
            }
            // equal up to the rounding of the scaling (a few ulp), or one digit apart on a
            // boundary tie that the two scalings break differently
            let ulps = 8.0 * f64::EPSILON * direct.abs().max(1e-300);
            let digit = 10f64.powf(v.abs().max(1e-300).log10().floor() - 8.0);
            let d = (fast - direct).abs();
            assert!(
                d <= ulps || d <= digit * 1.000_001,
                "{v:e}: {fast:e} vs {direct:e}"
            );
        }
    }
}
