//! One run being read: the role set with units and signs, the row accumulator every reader feeds
//! (conversion, non-finite and time-order counting in one place), and the finished [`ImportedRun`].

use std::collections::BTreeMap;

use serde::Serialize;

use crate::{JointStates, LogsError, Role, RunSignals, Unit};

/// The roles a reader fills, each with its source unit and sign. `time` is always present.
#[derive(Clone, Debug, PartialEq)]
pub struct RoleMap {
    /// `(role, source unit, negate)`, `time` first, no role twice.
    entries: Vec<(Role, Unit, bool)>,
}

impl RoleMap {
    /// A map of `roles` (time added first if absent) in SI units, not negated.
    pub fn si(roles: &[Role]) -> Self {
        let mut entries = vec![(Role::Time, Role::Time.si(), false)];
        for &r in roles {
            if !entries.iter().any(|e| e.0 == r) {
                entries.push((r, r.si(), false));
            }
        }
        Self { entries }
    }

    /// Sets the source unit of a role (an error if the role is not mapped).
    pub fn set_unit(&mut self, role: Role, unit: Unit) -> Result<(), LogsError> {
        let e = self.entry(role, "--unit")?;
        e.1 = unit;
        Ok(())
    }

    /// Negates a role (sign convention; an error if the role is not mapped or already negated: two
    /// `--negate` of one role would cancel silently).
    pub fn negate(&mut self, role: Role) -> Result<(), LogsError> {
        let e = self.entry(role, "--negate")?;
        if e.2 {
            return Err(LogsError::Usage(format!(
                "--negate {role} is given twice (it would cancel itself)"
            )));
        }
        e.2 = true;
        Ok(())
    }

    fn entry(&mut self, role: Role, what: &str) -> Result<&mut (Role, Unit, bool), LogsError> {
        let mapped = self.roles().map(Role::name).collect::<Vec<_>>().join(", ");
        self.entries
            .iter_mut()
            .find(|e| e.0 == role)
            .ok_or_else(|| {
                LogsError::Usage(format!(
                    "{what} {role}: role {role} is not read from this log (mapped: {mapped})"
                ))
            })
    }

    /// The roles, `time` first.
    pub fn roles(&self) -> impl Iterator<Item = Role> + '_ {
        self.entries.iter().map(|e| e.0)
    }

    /// Number of roles (including time).
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Never empty (time is always there).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// True if `role` is mapped.
    pub fn has(&self, role: Role) -> bool {
        self.entries.iter().any(|e| e.0 == role)
    }

    /// One line per role: unit conversion and sign, for the sidecar.
    pub fn conversions(&self) -> Vec<String> {
        self.entries
            .iter()
            .map(|&(r, u, neg)| {
                let si = r.si();
                let mut s = if u.name == si.name {
                    format!("{r}: {} (no conversion)", si.name)
                } else {
                    format!("{r}: {} x {} -> {}", u.name, u.factor, si.name)
                };
                if neg {
                    s.push_str(", negated");
                }
                s
            })
            .collect()
    }
}

/// What happened while reading one run (goes into the dataset sidecar).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RunReport {
    /// Source file as given.
    pub source: String,
    /// Format (`csv`, `mcap`, `mat`).
    pub format: String,
    /// Rows (CSV lines, messages, log ticks) read.
    pub rows_read: u64,
    /// Rows used.
    pub rows_used: u64,
    /// Rows dropped for a non-finite value, per role (a row can count in several roles).
    pub non_finite: BTreeMap<String, u64>,
    /// Rows dropped because their time was not after the previous used row's.
    pub time_not_increasing: u64,
    /// Rows dropped for another reason, by reason (e.g. `joint not in message`).
    pub skipped: BTreeMap<String, u64>,
    /// Which source field or column each role came from.
    pub sources: BTreeMap<String, String>,
    /// Unit and sign conversion per role.
    pub conversions: Vec<String>,
    /// Anything else the reader did (time origin, chunking rule, …).
    pub notes: Vec<String>,
    /// What the user must know (a signal not used for the whole run and why, a recording that was
    /// not closed); `frictl import` prints them.
    pub warnings: Vec<String>,
}

impl RunReport {
    /// What a user should see of this report, one line each, prefixed by the source: the reader's
    /// warnings, the rows dropped for a non-finite value (per role) and for a time that did not
    /// increase.
    pub fn warning_lines(&self) -> Vec<String> {
        let src = &self.source;
        let mut out: Vec<String> = self
            .warnings
            .iter()
            .map(|w| format!("{src}: {w}"))
            .collect();
        let nf: u64 = self.non_finite.values().sum();
        if nf > 0 {
            let per: Vec<String> = self
                .non_finite
                .iter()
                .map(|(k, v)| format!("{k}: {v}"))
                .collect();
            out.push(format!(
                "{src}: {nf} non-finite values dropped ({})",
                per.join(", ")
            ));
        }
        if self.time_not_increasing > 0 {
            out.push(format!(
                "{src}: {} rows whose time did not increase dropped",
                self.time_not_increasing
            ));
        }
        out
    }
}

/// One imported run: the signals for the pipeline and the report of how they were read.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedRun {
    /// Run name (the file stem; made unique by [`unique_run_names`]).
    pub name: String,
    /// The labelled joints' names, `signals`' first (empty names when the spec named none).
    pub joints: Vec<String>,
    /// The (first) labelled joint's signals, SI units, project signs.
    pub signals: RunSignals,
    /// Further labelled joints' signals, on the same clock as `signals` (empty for one joint).
    pub other_joints: Vec<RunSignals>,
    /// The positions of every joint read for the whole-body τ_ID, on the same clock (`None` when
    /// not asked for).
    pub state: Option<JointStates>,
    /// How they were read.
    pub report: RunReport,
}

impl ImportedRun {
    /// Every labelled joint's signals, `signals` first.
    pub fn joint_signals(&self) -> impl Iterator<Item = &RunSignals> {
        std::iter::once(&self.signals).chain(&self.other_joints)
    }
}

/// The whole-body state a reader fills: joints by name, which have logged velocities and
/// accelerations, the source units of each, and whether a base quaternion `[x, y, z, w]` is read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateLayout {
    /// Joint names (the log's, matched to the URDF by name).
    pub names: Vec<String>,
    /// Per joint: a velocity is read.
    pub qdot: Vec<bool>,
    /// Per joint: an acceleration is read.
    pub qddot: Vec<bool>,
    /// Multiply q, q̇, q̈ by these for SI units (the `s`, `sdot`, `sddot` roles' units).
    pub factors: [f64; 3],
    /// Four more columns: an orientation quaternion `[x, y, z, w]` in the world, the root link's
    /// or that of [`Self::base_frame`].
    pub base_quat: bool,
    /// The frame whose orientation the quaternion is, as the log names it (a `.mat` orientation
    /// sensor's name, an MCAP `Imu`'s `header.frame_id`; `None`: the root link's). The label finds
    /// it in the URDF ([`frictionless_ident::preprocess::JointStates::base_frame`]).
    pub base_frame: Option<String>,
    /// Six more columns per frame named: a measured wrench applied to the robot there, `[fx, fy,
    /// fz]` [N] then `[mx, my, mz]` [N·m] in the frame's coordinates.
    pub wrenches: Vec<String>,
}

impl StateLayout {
    /// Positions only, in SI units.
    pub fn positions(names: Vec<String>) -> Self {
        let n = names.len();
        Self {
            names,
            qdot: vec![false; n],
            qddot: vec![false; n],
            factors: [1.0; 3],
            base_quat: false,
            base_frame: None,
            wrenches: Vec::new(),
        }
    }

    /// Values per row: per joint q, then q̇ and q̈ when read; then the quaternion.
    pub fn width(&self) -> usize {
        self.names.len()
            + self.qdot.iter().filter(|x| **x).count()
            + self.qddot.iter().filter(|x| **x).count()
            + if self.base_quat { 4 } else { 0 }
            + 6 * self.wrenches.len()
    }

    /// `(what, factor)` of each value of a row, in row order (`q:NAME`, `qdot:NAME`, …).
    fn columns(&self) -> Vec<(String, f64)> {
        let mut out = Vec::with_capacity(self.width());
        for (k, n) in self.names.iter().enumerate() {
            out.push((format!("q:{n}"), self.factors[0]));
            if self.qdot[k] {
                out.push((format!("qdot:{n}"), self.factors[1]));
            }
            if self.qddot[k] {
                out.push((format!("qddot:{n}"), self.factors[2]));
            }
        }
        if self.base_quat {
            for c in ["x", "y", "z", "w"] {
                out.push((format!("base_quat_{c}"), 1.0));
            }
        }
        for f in &self.wrenches {
            for c in WRENCH_COMPONENTS {
                out.push((format!("wrench:{f}:{c}"), 1.0));
            }
        }
        out
    }
}

/// The components of a wrench, in column order (`{c}` of a wrench template).
pub const WRENCH_COMPONENTS: [&str; 6] = ["fx", "fy", "fz", "mx", "my", "mz"];

/// `x` (a quaternion) or `−x`, whichever continues the sign of the last finite one in `prev`
/// (updated): q and −q are the same rotation, and interpolating across a sign flip passes near
/// zero. A non-finite `x` is returned as is.
pub(crate) fn continue_sign(prev: &mut Option<[f64; 4]>, x: [f64; 4]) -> [f64; 4] {
    if !x.iter().all(|c| c.is_finite()) {
        return x;
    }
    let y = match prev {
        Some(p) if p.iter().zip(&x).map(|(u, v)| u * v).sum::<f64>() < 0.0 => x.map(|c| -c),
        _ => x,
    };
    *prev = Some(y);
    y
}

/// Where a streaming read hands its rows: blocks of `block_rows` rows (the last one shorter), each
/// an [`ImportedRun`] of those rows only, with a report that holds only the source and format (the
/// run's report comes with the run at the end, whose signals are then empty). A sink's error stops the read.
pub struct BlockSink<'a> {
    /// Rows per block (at least 1).
    pub block_rows: usize,
    /// Takes each block.
    pub sink: &'a mut dyn FnMut(ImportedRun) -> Result<(), String>,
}

/// Accumulates rows of raw values in the map's role order, converts them and counts the rejects.
pub(crate) struct RunBuilder<'s> {
    map: RoleMap,
    /// Labelled joints: the row holds time, then each joint's roles (all but time) in map order.
    joints: Vec<String>,
    state: Option<StateLayout>,
    /// `(what, factor)` of the state's values, after the joints' (see [`StateLayout::columns`]).
    state_cols: Vec<(String, f64)>,
    cols: Vec<Vec<f64>>,
    chunk: Vec<u32>,
    report: RunReport,
    row: Vec<f64>,
    last_t: f64,
    first_backwards: Option<String>,
    /// Rows whose time equals the previous used row's (a subset of `time_not_increasing`).
    time_repeated: u64,
    /// Streaming: the rows go to the sink in blocks instead of being held.
    stream: Option<BlockSink<'s>>,
}

impl<'s> RunBuilder<'s> {
    /// A builder for labelled `joints` (at least one) with the same roles, and a whole-body state.
    pub(crate) fn with_joints(
        map: RoleMap,
        mut joints: Vec<String>,
        state: Option<StateLayout>,
        source: &str,
        format: &str,
    ) -> Self {
        if joints.is_empty() {
            joints.push(String::new());
        }
        let n_joints = joints.len();
        let state_cols = state.as_ref().map(StateLayout::columns).unwrap_or_default();
        let n = 1 + (map.len() - 1) * n_joints + state_cols.len();
        let mut conversions = map.conversions();
        if let Some(st) = &state {
            conversions.push(format!(
                "whole-body state of {} joints: q x {}, qdot x {}, qddot x {} (the s, sdot, sddot units)",
                st.names.len(),
                st.factors[0],
                st.factors[1],
                st.factors[2]
            ));
        }
        let report = RunReport {
            source: source.to_string(),
            format: format.to_string(),
            conversions,
            ..RunReport::default()
        };
        Self {
            map,
            joints,
            state,
            state_cols,
            cols: vec![Vec::new(); n],
            chunk: Vec::new(),
            report,
            row: vec![0.0; n],
            last_t: f64::NEG_INFINITY,
            first_backwards: None,
            time_repeated: 0,
            stream: None,
        }
    }

    /// Hands the rows to `stream` in blocks instead of holding them (see [`BlockSink`]).
    pub(crate) fn streaming(mut self, stream: Option<BlockSink<'s>>) -> Self {
        self.stream = stream;
        self
    }

    /// Passes the rows held to the sink, if streaming.
    fn flush(&mut self) -> Result<(), LogsError> {
        let Some(s) = self.stream.take() else {
            return Ok(());
        };
        let r = if self.chunk.is_empty() {
            Ok(())
        } else {
            let (signals, state) = self.take_columns();
            let mut joints = signals.into_iter();
            let block = ImportedRun {
                name: String::new(),
                joints: self.joints.clone(),
                signals: joints.next().unwrap_or_default(),
                other_joints: joints.collect(),
                state,
                // The source names the block's rows in what is said about them (e.g. the
                // plausibility check of a streamed import).
                report: RunReport {
                    source: self.report.source.clone(),
                    format: self.report.format.clone(),
                    ..RunReport::default()
                },
            };
            (s.sink)(block).map_err(|msg| LogsError::Format {
                path: self.report.source.clone(),
                msg,
            })
        };
        self.stream = Some(s);
        r
    }

    /// The rows held, as each labelled joint's signals and the whole-body state; leaves the
    /// builder with no rows.
    fn take_columns(&mut self) -> (Vec<RunSignals>, Option<JointStates>) {
        let per_joint = self.map.len() - 1;
        let mut cols = self.cols.iter_mut().map(std::mem::take);
        let time = cols.next().unwrap_or_default();
        let chunk = std::mem::take(&mut self.chunk);
        let roles: Vec<Role> = self.map.roles().skip(1).collect();
        let mut joints = Vec::with_capacity(self.joints.len());
        for _ in 0..self.joints.len() {
            let mut sig = RunSignals {
                time_s: time.clone(),
                chunk: chunk.clone(),
                ..RunSignals::default()
            };
            for (&role, col) in roles.iter().zip(cols.by_ref().take(per_joint)) {
                set_role(&mut sig, role, col);
            }
            joints.push(sig);
        }
        let state = self.state.as_ref().map(|layout| {
            let mut st = JointStates {
                names: layout.names.clone(),
                ..JointStates::default()
            };
            for k in 0..layout.names.len() {
                st.q.push(cols.next().unwrap_or_default());
                st.qdot
                    .push(layout.qdot[k].then(|| cols.next().unwrap_or_default()));
                st.qddot
                    .push(layout.qddot[k].then(|| cols.next().unwrap_or_default()));
            }
            if layout.base_quat {
                st.base_quat_xyzw = Some(std::array::from_fn(|_| cols.next().unwrap_or_default()));
                st.base_frame = layout.base_frame.clone();
            }
            for f in &layout.wrenches {
                st.wrenches
                    .push(frictionless_ident::preprocess::FrameWrench {
                        frame: f.clone(),
                        series: std::array::from_fn(|_| cols.next().unwrap_or_default()),
                    });
            }
            st
        });
        (joints, state)
    }

    /// Names the frame whose orientation the state's quaternion is (see
    /// [`StateLayout::base_frame`]), when it is learnt while reading (an MCAP `Imu`'s frame).
    pub(crate) fn set_base_frame(&mut self, frame: &str) {
        if let Some(l) = self.state.as_mut()
            && l.base_frame.as_deref() != Some(frame)
        {
            l.base_frame = Some(frame.to_string());
        }
    }

    pub(crate) fn report_mut(&mut self) -> &mut RunReport {
        &mut self.report
    }

    /// The row buffer to fill with raw values, in [`RoleMap::roles`] order (time first).
    pub(crate) fn row_mut(&mut self) -> &mut [f64] {
        &mut self.row
    }

    /// Counts a row that was read but skipped for `reason`.
    pub(crate) fn skip(&mut self, reason: &str) {
        self.report.rows_read += 1;
        *self.report.skipped.entry(reason.to_string()).or_insert(0) += 1;
    }

    /// Takes the row in [`Self::row_mut`] (raw units) at `where_` (e.g. `line 12`) with chunk id
    /// `chunk`; streaming, a full block goes to the sink (its error is returned).
    pub(crate) fn push(
        &mut self,
        where_: impl FnOnce() -> String,
        chunk: u32,
    ) -> Result<(), LogsError> {
        self.report.rows_read += 1;
        let mut ok = true;
        let per_joint = self.map.entries.len() - 1;
        let n_role_values = 1 + per_joint * self.joints.len();
        for (k, slot) in self.row.iter_mut().enumerate() {
            let (factor, what): (f64, &str) = if k < n_role_values {
                let e = if k == 0 {
                    &self.map.entries[0]
                } else {
                    &self.map.entries[1 + (k - 1) % per_joint]
                };
                (e.1.factor * if e.2 { -1.0 } else { 1.0 }, e.0.name())
            } else {
                let c = &self.state_cols[k - n_role_values];
                (c.1, &c.0)
            };
            let v = *slot * factor;
            *slot = v;
            if !v.is_finite() {
                ok = false;
                *self.report.non_finite.entry(what.to_string()).or_insert(0) += 1;
            }
        }
        if !ok {
            return Ok(());
        }
        let t = self.row[0];
        if t <= self.last_t {
            self.report.time_not_increasing += 1;
            if t == self.last_t {
                self.time_repeated += 1;
            }
            if self.first_backwards.is_none() {
                self.first_backwards = Some(where_());
            }
            return Ok(());
        }
        self.last_t = t;
        for (c, v) in self.cols.iter_mut().zip(&self.row) {
            c.push(*v);
        }
        self.chunk.push(chunk);
        self.report.rows_used += 1;
        match &self.stream {
            Some(s) if self.chunk.len() >= s.block_rows.max(1) => self.flush(),
            _ => Ok(()),
        }
    }

    /// The finished run; errors when nothing is usable or more than 1 % of the rows go back in time.
    pub(crate) fn finish(mut self, path: &str, name: String) -> Result<ImportedRun, LogsError> {
        let r = &self.report;
        if r.rows_read > 0 && r.time_not_increasing * 100 <= r.rows_read && r.rows_used >= 2 {
            self.flush()?;
        }
        let r = &self.report;
        if r.rows_read == 0 {
            return Err(LogsError::Empty {
                path: path.to_string(),
                what: "no data rows".into(),
            });
        }
        if r.time_not_increasing * 100 > r.rows_read && self.time_repeated * 2 > r.rows_read {
            return Err(LogsError::Format {
                path: path.to_string(),
                msg: format!(
                    "the time does not advance: {} of {} rows have the time of the row before \
                     (first at {}); a constant column is not a time: check --column time=…",
                    self.time_repeated,
                    r.rows_read,
                    self.first_backwards.take().unwrap_or_default()
                ),
            });
        }
        if r.time_not_increasing * 100 > r.rows_read {
            return Err(LogsError::NonMonotonic {
                path: path.to_string(),
                count: r.time_not_increasing,
                rows: r.rows_read,
                where_: self.first_backwards.take().unwrap_or_default(),
            });
        }
        if r.rows_used < 2 {
            let nf: Vec<String> = r
                .non_finite
                .iter()
                .map(|(k, v)| format!("{k}: {v}"))
                .collect();
            return Err(LogsError::Empty {
                path: path.to_string(),
                what: format!(
                    "fewer than 2 usable rows of {} (non-finite per role: {})",
                    r.rows_read,
                    if nf.is_empty() {
                        "none".into()
                    } else {
                        nf.join(", ")
                    }
                ),
            });
        }
        let (joints, state) = self.take_columns();
        let mut joints = joints.into_iter();
        Ok(ImportedRun {
            name,
            joints: self.joints,
            signals: joints.next().unwrap_or_default(),
            other_joints: joints.collect(),
            state,
            report: self.report,
        })
    }
}

/// Puts a role's column into its slot of `sig`.
fn set_role(sig: &mut RunSignals, role: Role, col: Vec<f64>) {
    let slot = match role {
        Role::Time => {
            sig.time_s = col;
            return;
        }
        Role::S => &mut sig.s_rad,
        Role::Sdot => &mut sig.sdot_rad_s,
        Role::Sddot => &mut sig.sddot_rad_s2,
        Role::Theta => &mut sig.theta_motor_rad,
        Role::Omega => &mut sig.omega_motor_rad_s,
        Role::Current => &mut sig.current_a,
        Role::TauJoint => &mut sig.tau_joint_nm,
        Role::TauMotor => &mut sig.tau_motor_nm,
        Role::TauF => &mut sig.tau_f_nm,
        Role::Temperature => &mut sig.temperature_c,
    };
    *slot = Some(col);
}

/// Makes run names unique in place (`a`, `a` → `a`, `a_2`).
pub fn unique_run_names(runs: &mut [ImportedRun]) {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let taken: Vec<String> = runs.iter().map(|r| r.name.clone()).collect();
    for run in runs.iter_mut() {
        let n = seen.entry(run.name.clone()).or_insert(0);
        *n += 1;
        if *n > 1 {
            let mut k = *n;
            while taken.contains(&format!("{}_{k}", run.name)) {
                k += 1;
            }
            run.name = format!("{}_{k}", run.name);
        }
    }
}

/// A warning when a given friction label looks like the opposite sign convention: friction opposes
/// motion, so τ_F correlates positively with sign(ṡ) on moving samples (|ṡ| > 0.01 rad/s, valid);
/// `None` when it does or when there are too few moving samples (< 100).
pub fn label_sign_warning(ds: &frictionless_dataset::Dataset) -> Option<String> {
    let (mut sum, mut n) = (0.0, 0usize);
    let (mut sx, mut sy, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..ds.len() {
        let (v, f) = (ds.sdot_rad_s[k], ds.tau_f_label_nm[k]);
        if ds.valid[k] && v.abs() > 0.01 && f.is_finite() {
            let x = v.signum();
            sum += x * f;
            sx += x;
            sy += f;
            sxx += x * x;
            syy += f * f;
            n += 1;
        }
    }
    if n < 100 {
        return None;
    }
    let nf = n as f64;
    let cov = sum / nf - sx / nf * sy / nf;
    let den = ((sxx / nf - (sx / nf).powi(2)) * (syy / nf - (sy / nf).powi(2))).sqrt();
    let corr = if den > 0.0 { cov / den } else { 0.0 };
    (corr < 0.0).then(|| {
        format!(
            "the friction label is anti-correlated with sign(sdot) (correlation {corr:.2} on {n} moving samples): \
             friction opposes motion, so the log probably uses the opposite sign convention (try --negate tau_f)"
        )
    })
}
