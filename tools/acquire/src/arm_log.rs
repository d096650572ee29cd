//! The log of a torque-sensed arm: what `frictl acquire --sensor torque` writes instead of the robot's
//! motor-encoder log.
//!
//! What it is: [`ArmLog`], a CSV writer for the rows of an offline run that keeps only what a typical
//! torque-sensed arm logs — joint position and velocity, motor current, the joint torque sensor
//! ([`frictionless_sim::torque_sensor`]), the temperature if the joint has a sensor — and no motor
//! encoder (θ, ω absent), optionally at a lower rate with jittered timestamps, plus the simulator's true
//! friction for scoring; [`arm_columns`] documents the columns. It is meant as input to `frictl import
//! csv` (roles `time`, `s`, `sdot`, `current`, `tau_joint`, `temperature`; `tau_f` from the truth
//! column for a `given` label).
//!
//! What it is not: the motor-encoder log of the paper's pipeline ([`crate::log::CsvLog`], read by
//! `frictl preprocess`) or a live logger (it needs the simulator's truth for the torque sensor).

use std::io::Write;

use frictionless_dataset::ColumnDoc;
use frictionless_sim::torque_sensor::{TorqueSensor, TorqueSensorParams};

use crate::log::round_significant;
use crate::protocol::{AcquireError, LogRow};

const fn col(name: &'static str, unit: &'static str, doc: &'static str) -> ColumnDoc {
    ColumnDoc { name, unit, doc }
}

/// Columns of an arm log, in file order (`temperature_c` only with a temperature sensor).
const ARM_COLUMNS: &[ColumnDoc] = &[
    col(
        "time_s",
        "s",
        "logger timestamp: sample time plus the logger's jitter (uniform, at most --jitter-ms)",
    ),
    col("q_rad", "rad", "joint encoder, quantised to 2*pi/2^18"),
    col(
        "dq_rad_s",
        "rad/s",
        "joint velocity: joint-encoder difference over the last 5 samples (1 kHz) divided by 5 ms",
    ),
    col(
        "current_a",
        "A",
        "measured motor current (robot convention: motor torque at the joint = r_signed*kt*i)",
    ),
    col(
        "tau_joint_nm",
        "Nm",
        "joint torque sensor at the output flange (link side, positive along q): tau_t - tau_Fj + offset + noise",
    ),
    col(
        "temperature_c",
        "degC",
        "winding temperature, 0.1 degC resolution",
    ),
    col(
        "tau_f_true_nm",
        "Nm",
        "simulator truth, for scoring only: joint-side friction tau_Fm + tau_Fj",
    ),
];

/// Joint-velocity difference window [samples at the plant's rate].
const DQ_WINDOW: usize = 5;

/// The columns of an arm log.
pub fn arm_columns(with_temperature: bool) -> Vec<ColumnDoc> {
    ARM_COLUMNS
        .iter()
        .filter(|c| with_temperature || c.name != "temperature_c")
        .copied()
        .collect()
}

/// How an arm log samples the run.
#[derive(Clone, Debug, PartialEq)]
pub struct ArmLogOptions {
    /// Write every n-th sample of the 1 kHz run (1: 1 kHz, 2: 500 Hz); ≥ 1.
    pub every_samples: u32,
    /// Timestamp jitter: uniform in ±this [s]; less than half the log period.
    pub jitter_s: f64,
    /// The plant's sample period [s].
    pub sample_period_s: f64,
    /// Whether the joint has a temperature sensor (else the column is left out).
    pub with_temperature: bool,
    /// The torque sensor.
    pub sensor: TorqueSensorParams,
    /// Seed of the sensor noise and the jitter.
    pub seed: u64,
}

/// CSV writer of an arm log (see the module doc).
pub struct ArmLog<W: Write> {
    out: W,
    opts: ArmLogOptions,
    sensor: TorqueSensor,
    /// The last `DQ_WINDOW + 1` joint-encoder readings (ring).
    q_hist: [f64; DQ_WINDOW + 1],
    n: u64,
    rows: u64,
    float: zmij::Buffer,
    line: Vec<u8>,
}

impl<W: Write> ArmLog<W> {
    /// Starts a log and writes the header.
    pub fn new(mut out: W, opts: ArmLogOptions) -> Result<Self, AcquireError> {
        let bad = |m: String| AcquireError::Sink(m);
        if opts.every_samples == 0 {
            return Err(bad("arm log: every_samples must be >= 1".into()));
        }
        let period = f64::from(opts.every_samples) * opts.sample_period_s;
        if !(opts.jitter_s.is_finite() && opts.jitter_s >= 0.0 && opts.jitter_s < 0.5 * period) {
            return Err(bad(format!(
                "arm log: jitter {} s must be >= 0 and below half the log period ({period} s), so timestamps stay in order",
                opts.jitter_s
            )));
        }
        let sensor = TorqueSensor::new(opts.sensor.clone(), opts.seed)
            .map_err(|e| bad(format!("arm log: {e}")))?;
        let header: Vec<&str> = arm_columns(opts.with_temperature)
            .iter()
            .map(|c| c.name)
            .collect();
        writeln!(out, "{}", header.join(",")).map_err(|e| bad(e.to_string()))?;
        Ok(Self {
            out,
            opts,
            sensor,
            q_hist: [f64::NAN; DQ_WINDOW + 1],
            n: 0,
            rows: 0,
            float: zmij::Buffer::new(),
            line: Vec::with_capacity(256),
        })
    }

    /// Takes one 1 kHz row of the run (it must carry the simulator's truth); writes it if it falls on
    /// the log's period.
    pub fn write(&mut self, row: &LogRow) -> Result<(), AcquireError> {
        let truth = row.truth.ok_or_else(|| {
            AcquireError::Sink(
                "arm log: a row without the simulator's truth (the torque sensor needs it)".into(),
            )
        })?;
        let m = &row.meas;
        self.q_hist.rotate_left(1);
        self.q_hist[DQ_WINDOW] = m.s_rad;
        // The sensor is read every sample (one noise stream whatever the log rate).
        let tau_joint = self.sensor.read_nm(&truth);
        let k = self.n;
        self.n += 1;
        if !k.is_multiple_of(u64::from(self.opts.every_samples)) {
            return Ok(());
        }
        let dq = if self.q_hist[0].is_finite() {
            (self.q_hist[DQ_WINDOW] - self.q_hist[0])
                / (DQ_WINDOW as f64 * self.opts.sample_period_s)
        } else if k == 0 {
            0.0
        } else {
            // Fewer than DQ_WINDOW samples so far: the difference over what there is.
            let first = self.q_hist.iter().position(|q| q.is_finite()).unwrap_or(0);
            let span = (DQ_WINDOW - first) as f64 * self.opts.sample_period_s;
            (self.q_hist[DQ_WINDOW] - self.q_hist[first]) / span
        };
        let t = self.sensor.stamp_s(m.time_s, self.opts.jitter_s);
        let mut values = vec![t, m.s_rad, dq, m.i_meas_a, tau_joint];
        if self.opts.with_temperature {
            values.push(m.temperature_c);
        }
        values.push(truth.tau_f_nm);
        self.line.clear();
        for (j, v) in values.into_iter().enumerate() {
            if j > 0 {
                self.line.push(b',');
            }
            self.line
                .extend_from_slice(self.float.format(round_significant(v)).as_bytes());
        }
        self.line.push(b'\n');
        self.out
            .write_all(&self.line)
            .map_err(|e| AcquireError::Sink(e.to_string()))?;
        self.rows += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> Result<W, AcquireError> {
        self.out
            .flush()
            .map_err(|e| AcquireError::Sink(e.to_string()))?;
        Ok(self.out)
    }
}
