//! The YARP robot logger's MATLAB v7.3 files (HDF5 with a 512-byte MAT userblock; layout in
//! `docs/robot-logs.md` §1–§4), read with `hdf5-metno` through the system HDF5 library.
//!
//! One joint is picked by name in each channel's `elements_names` (cellstr: object references to
//! UTF-16 char arrays under `/#refs#`). Signals: s = `joints_state/positions`, θ =
//! `motors_state/positions`, ω = `motors_state/velocities`, current = `motors_state/currents`,
//! temperature = `motors_state/temperatures` (when logged); ṡ and s̈ are left to the pipeline's
//! smoother, as the authors do. Time is `timestamps − t₀` of `joints_state/positions`: its ticks
//! are the reference time base, and every other joint channel is read on its own `timestamps` and
//! aligned onto them (`Aligned`: a tick at a sample takes it, a tick between two close samples
//! is interpolated, a tick in a gap of the channel drops its row, counted and warned, and the gap
//! closes the chunk). Chunks are
//! the spans of the exogenous `current_control/motors/desired/current` stream between its gaps
//! larger than the given gap (1 s, the authors' rule); robot ticks outside every span are skipped
//! (counted). Without that channel the whole file is one stream split by the pipeline's gap rule.
//!
//! The whole-body state ([`MatSpec::state_joints`]) is every joint of `joints_state/positions`, and,
//! when asked for ([`MatState`]), the joints' logged velocities and accelerations, the root link's
//! orientation (roll/pitch/yaw or a quaternion) and measured wrenches at URDF frames, each from a
//! channel on the same ticks.
//!
//! Bounded: each channel's `data` (N, 1, n) is read as hyperslabs of 65 536 rows (streamed: of the
//! sink's block) of the one joint's column (the state's channels: every column), so memory is the
//! joints' signals, whatever the file size. Sizes are checked before
//! anything is read: a cellstr holds at most [`MAX_NAMES`] names of at most [`MAX_NAME_UNITS`] code
//! units, and a dataset may not declare more bytes than the file could hold ([`check_stored`]: an
//! HDF5 dataset whose chunks were never written reads as fill values of any declared size).

use std::io::Read;
use std::path::Path;

use hdf5_metno as h5;
use hdf5_metno::ObjectReference1;

use crate::run::RunBuilder;
use crate::{ImportedRun, LogsError, Progress, Role, RoleMap, open_regular};

/// How to read a `.mat` log.
#[derive(Clone, Debug, PartialEq)]
pub struct MatSpec {
    /// Labelled joint names (empty: the one named in the desired-current channel).
    pub joints: Vec<String>,
    /// Label every joint of the whole-body state instead (needs `state_joints`).
    pub all_joints: bool,
    /// Read the whole-body state: every joint of `joints_state/positions`; the names not in this
    /// list (the URDF's joints) are listed in the report.
    pub state_joints: Option<Vec<String>>,
    /// Roles to negate.
    pub negate: Vec<Role>,
    /// A gap of the desired-current stream larger than this closes a chunk [s].
    pub desired_gap_s: f64,
}

/// What a `.mat` log adds to the whole-body state beyond the joint positions (read only with
/// [`MatSpec::state_joints`]; [`read_state`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MatState {
    /// The root link's orientation in the world, for the whole-body state: a channel under
    /// `robot_logger_device` on the ticks of `joints_state/positions`, of 3 elements roll, pitch,
    /// yaw [rad] (R = Rz(y)·Ry(p)·Rx(r): an orientation sensor's YARP roll-pitch-yaw, which the
    /// logger converts to radians; e.g. `orientations/waist_imu_0`, elements `r p y`), or of 4, the
    /// quaternion `x y z w` (e.g. `frames/<root>/<frame>/orientation`, elements `qx qy qz qw`).
    pub base_orientation: Option<String>,
    /// Take the whole-body state's q̇ and q̈ as logged (`joints_state/velocities`,
    /// `joints_state/accelerations`, when they have the elements of `joints_state/positions`)
    /// instead of the smoother's estimates from q (the default, as the authors do: a logger may
    /// write encoder accelerations that the firmware does not estimate).
    pub logged_derivatives: bool,
    /// Measured wrenches applied to the robot: `(URDF frame, channel)`, the channel (e.g.
    /// `FTs/l_foot_front_ft` or `cartesian_wrenches/<name>`) of 6 elements `f_x f_y f_z` [N], `mu_x
    /// mu_y mu_z` [N·m] in the frame's coordinates about its origin.
    pub wrenches: Vec<(String, String)>,
}

/// A quaternion `[x, y, z, w]` of roll, pitch, yaw [rad] with R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn rpy_to_quat_xyzw(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

/// A channel of the whole-body state read whole per block: its `data` (N, 1, m), `m`, and the
/// column of each component in its canonical order.
struct StateChannel {
    data: h5::Dataset,
    width: usize,
    order: Vec<usize>,
}

/// The YARP robot logger's element names of an orientation sensor (roll, pitch, yaw [rad]).
const RPY_NAMES: [&str; 3] = ["r", "p", "y"];
/// The logger's element names of a frame's orientation quaternion (`frames/<root>/<frame>/orientation`).
const QUAT_NAMES: [&str; 4] = ["qx", "qy", "qz", "qw"];
/// The logger's element names of a force-torque sensor or a cartesian wrench.
const WRENCH_NAMES: [&str; 6] = ["f_x", "f_y", "f_z", "mu_x", "mu_y", "mu_z"];

/// Opens the channel `name` (a path under the root) that the state needs: present, (n, 1, m) with
/// `m` the length of one of `known` (or of `widths` when `known` is empty); the error names the
/// channel and what was found. When its `elements_names` are the `known` names in any order the
/// components are taken by name, otherwise in order (said in `notes`).
#[allow(clippy::too_many_arguments)]
fn state_channel(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    name: &str,
    n: usize,
    known: &[&[&str]],
    widths: &[usize],
    what: &str,
    notes: &mut Vec<String>,
) -> Result<StateChannel, LogsError> {
    let fmt = |msg: String| LogsError::Format {
        path: path.display().to_string(),
        msg,
    };
    let group = root
        .group(name)
        .map_err(|_| fmt(format!("{what}: no channel `{ROOT}/{name}`")))?;
    let data = group.dataset("data").map_err(|_| {
        fmt(format!(
            "{what}: the channel `{ROOT}/{name}` has no `data` (nothing logged)"
        ))
    })?;
    let widths: Vec<usize> = if known.is_empty() {
        widths.to_vec()
    } else {
        known.iter().map(|k| k.len()).collect()
    };
    let shape = data.shape();
    let ok = shape.len() == 3 && shape[0] == n && shape[1] == 1 && widths.contains(&shape[2]);
    if !ok {
        return Err(fmt(format!(
            "{what}: `{name}/data` has shape {shape:?}; expected ({n}, 1, {}), on the ticks of \
             joints_state/positions",
            widths
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(" or ")
        )));
    }
    check_stored(path, &format!("{name}/data"), &data)?;
    let width = shape[2];
    let mut order: Vec<usize> = (0..width).collect();
    if let Some(names) = known.iter().find(|k| k.len() == width) {
        let logged = group
            .dataset("elements_names")
            .and_then(|d| cellstr(file, &d))
            .unwrap_or_default();
        let by_name: Option<Vec<usize>> = names
            .iter()
            .map(|c| logged.iter().position(|l| l == c))
            .collect();
        match by_name {
            Some(o) => order = o,
            None => notes.push(format!(
                "{name}: elements_names {logged:?} are not {names:?}: taken in that order"
            )),
        }
    }
    Ok(StateChannel { width, data, order })
}

impl StateChannel {
    /// Rows `a..e`, every element, the columns in the canonical order.
    fn block(&self, path: &Path, a: usize, e: usize) -> Result<ndarray::Array2<f64>, LogsError> {
        let v: ndarray::Array2<f64> = self
            .data
            .read_slice_2d(ndarray::s![a..e, 0, ..])
            .map_err(|x| h5err(path, "state channel data", x))?;
        if self.order.iter().enumerate().all(|(k, &c)| k == c) {
            return Ok(v);
        }
        Ok(v.select(ndarray::Axis(1), &self.order))
    }
}

const ROOT: &str = "robot_logger_device";
const DESIRED: &str = "current_control/motors/desired/current";
const BLOCK: usize = 1 << 16;
/// Most names a cellstr (`elements_names`) may hold (a robot has tens of joints).
pub const MAX_NAMES: usize = 1 << 16;
/// Longest name, in UTF-16 code units.
pub const MAX_NAME_UNITS: usize = 4096;
/// deflate's largest compression ratio is 1032:1 (RFC 1951: a 258-byte match per 2 bits): a dataset
/// that declares more than this many times its stored bytes (plus [`STORED_SLACK`]) holds unwritten
/// chunks, not data. MATLAB v7.3 compresses with deflate only.
const MAX_RATIO: u64 = 1032;
/// Small datasets pass [`check_stored`] whatever their storage (headers, fill-value defaults).
const STORED_SLACK: u64 = 1 << 20;

/// One channel: its `data` dataset and the labelled joints' columns.
struct Channel {
    data: h5::Dataset,
    cols: Vec<usize>,
}

/// A joint channel other than the positions, read on its own `timestamps` and aligned onto the
/// positions' ticks (the reference time base): a tick at one of the channel's stamps (within
/// [`SAME_TICK`] of the reference period) takes that sample; a tick between two stamps closer than
/// [`MAX_STEP`] periods (the larger of the two channels' periods) is interpolated linearly; a tick
/// in a longer gap of the channel, or before its first or after its last stamp, has no value and
/// its row is dropped (counted per channel). The channel is read forward in blocks of [`BLOCK`]
/// samples; the reference ticks come in increasing order (a tick not after the previous one keeps
/// the previous value: the run builder drops its row as a time that did not increase).
struct Aligned {
    /// The channel's name under the root (e.g. `motors_state/currents`).
    name: String,
    data: h5::Dataset,
    ts: h5::Dataset,
    /// Samples in the file.
    len: usize,
    /// The labelled joints' columns.
    cols: Vec<usize>,
    /// The next sample of the file not yet in the buffer.
    next: usize,
    /// Buffered stamps and, per labelled joint, values (finite, increasing stamps only).
    t: Vec<f64>,
    v: Vec<Vec<f64>>,
    /// Index into the buffer of the last stamp at or before the previous query.
    cursor: usize,
    /// A tick within this of a stamp takes its sample [s].
    same_s: f64,
    /// Longest span between two stamps interpolated across [s].
    max_step_s: f64,
    /// Samples whose stamp was not finite or not after the previous stamp (not used).
    bad_stamps: u64,
    /// Reference ticks taken at a stamp, interpolated, and without a value.
    exact: u64,
    interpolated: u64,
    missing: u64,
    /// Rows dropped for a tick without a value (counted by the reader: ticks outside the
    /// desired-current stream are not).
    dropped: u64,
    /// The previous query [s].
    last_query: f64,
}

/// A reference tick within this fraction of the reference period of a channel's stamp takes that
/// sample.
const SAME_TICK: f64 = 0.01;
/// Two stamps of a channel at most this many periods apart are interpolated between; a longer
/// span is a gap (its ticks have no value).
const MAX_STEP: f64 = 1.5;

/// The median step of the first (at most [`BLOCK`]) finite, increasing stamps of `ts`; `None`
/// with fewer than two.
fn median_step(path: &Path, ts: &h5::Dataset, len: usize) -> Result<Option<f64>, LogsError> {
    let t = read_ts(path, ts, 0, len.min(BLOCK))?;
    let mut d: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if d.is_empty() {
        return Ok(None);
    }
    d.sort_by(f64::total_cmp);
    Ok(Some(d[d.len() / 2]))
}

impl Aligned {
    /// The channel `name` with its data `ch`, aligned onto ticks of period `ref_step_s`.
    fn open(
        path: &Path,
        root: &h5::Group,
        name: &str,
        ch: Channel,
        len: usize,
        ref_step_s: f64,
    ) -> Result<Self, LogsError> {
        let ts = timestamps(path, root, name, len)?;
        let own = median_step(path, &ts, len)?.unwrap_or(ref_step_s);
        Ok(Self {
            name: name.to_string(),
            data: ch.data,
            ts,
            len,
            v: vec![Vec::new(); ch.cols.len()],
            cols: ch.cols,
            next: 0,
            t: Vec::new(),
            cursor: 0,
            same_s: SAME_TICK * ref_step_s,
            max_step_s: MAX_STEP * own.max(ref_step_s),
            bad_stamps: 0,
            exact: 0,
            interpolated: 0,
            missing: 0,
            dropped: 0,
            last_query: f64::NEG_INFINITY,
        })
    }

    /// Reads the next block of the file into the buffer, dropping what lies before the cursor;
    /// `false` at the end of the file.
    fn load(&mut self, path: &Path) -> Result<bool, LogsError> {
        if self.next >= self.len {
            return Ok(false);
        }
        let (a, e) = (self.next, (self.next + BLOCK).min(self.len));
        let t = read_ts(path, &self.ts, a, e)?;
        let mut cols = Vec::with_capacity(self.cols.len());
        for &c in &self.cols {
            let v: ndarray::Array1<f64> = self
                .data
                .read_slice_1d(ndarray::s![a..e, 0, c])
                .map_err(|x| h5err(path, &format!("{} data", self.name), x))?;
            cols.push(v);
        }
        self.t.drain(..self.cursor);
        for v in &mut self.v {
            v.drain(..self.cursor);
        }
        self.cursor = 0;
        for (k, &tk) in t.iter().enumerate() {
            if !(tk.is_finite() && self.t.last().is_none_or(|&l| tk > l)) {
                self.bad_stamps += 1;
                continue;
            }
            self.t.push(tk);
            for (v, c) in self.v.iter_mut().zip(&cols) {
                v.push(c[k]);
            }
        }
        self.next = e;
        Ok(true)
    }

    /// The labelled joints' values at reference tick `tq` into `out` (one per joint); `false`
    /// (and `out` untouched) when the channel has no value there. A tick not after the previous
    /// one leaves `out` as it is and answers `true`.
    fn at(&mut self, path: &Path, tq: f64, out: &mut [f64]) -> Result<bool, LogsError> {
        if tq.is_nan() || tq <= self.last_query {
            return Ok(true);
        }
        self.last_query = tq;
        // The buffer must hold a stamp after tq (or the file be read to its end).
        while self.t.last().is_none_or(|&l| l <= tq) && self.load(path)? {}
        while self.cursor + 1 < self.t.len() && self.t[self.cursor + 1] <= tq {
            self.cursor += 1;
        }
        let c = self.cursor;
        let Some(&t0) = self.t.get(c) else {
            self.missing += 1;
            return Ok(false);
        };
        let pick = |k: usize, out: &mut [f64], v: &[Vec<f64>]| {
            for (o, v) in out.iter_mut().zip(v) {
                *o = v[k];
            }
        };
        if (tq - t0).abs() <= self.same_s {
            pick(c, out, &self.v);
            self.exact += 1;
            return Ok(true);
        }
        let Some(&t1) = self.t.get(c + 1) else {
            self.missing += 1;
            return Ok(false);
        };
        if (t1 - tq).abs() <= self.same_s {
            pick(c + 1, out, &self.v);
            self.exact += 1;
            return Ok(true);
        }
        if t0 < tq && tq < t1 && t1 - t0 <= self.max_step_s {
            let w = (tq - t0) / (t1 - t0);
            for (o, v) in out.iter_mut().zip(&self.v) {
                *o = v[c] + w * (v[c + 1] - v[c]);
            }
            self.interpolated += 1;
            return Ok(true);
        }
        self.missing += 1;
        Ok(false)
    }

    /// What the alignment did, for the report: a note always, a warning when ticks had no value
    /// or stamps were unusable.
    fn say(&self, notes: &mut Vec<String>, warnings: &mut Vec<String>) {
        notes.push(format!(
            "{}: {} samples on its own timestamps aligned onto joints_state/positions: {} ticks \
             at a sample, {} interpolated (stamps at most {:.6} s apart), {} in its gaps (rows \
             dropped)",
            self.name, self.len, self.exact, self.interpolated, self.max_step_s, self.missing
        ));
        if self.dropped > 0 {
            warnings.push(format!(
                "{}: {} rows dropped: their ticks of joints_state/positions fall in gaps of its \
                 timestamps (longer than {:.6} s) or outside them",
                self.name, self.dropped, self.max_step_s
            ));
        }
        if self.bad_stamps > 0 {
            warnings.push(format!(
                "{}: {} samples whose timestamp was not finite or not after the previous one: \
                 not used",
                self.name, self.bad_stamps
            ));
        }
    }
}

fn h5err(path: &Path, what: &str, e: impl std::fmt::Display) -> LogsError {
    LogsError::Format {
        path: path.display().to_string(),
        msg: format!("{what}: {e}"),
    }
}

/// Refuses a dataset that declares more bytes than it stores beyond what compression explains
/// ([`MAX_RATIO`]): reading it would return fill values for as long as the declared size says.
fn check_stored(path: &Path, what: &str, ds: &h5::Dataset) -> Result<(), LogsError> {
    let elem = ds.dtype().map(|t| t.size()).unwrap_or(8).max(1) as u64;
    let declared = (ds.size() as u64).saturating_mul(elem);
    let stored = ds.storage_size();
    if declared
        > stored
            .saturating_mul(MAX_RATIO)
            .saturating_add(STORED_SLACK)
    {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: format!(
                "{what} declares {} elements ({declared} bytes) but the file stores {stored} bytes \
                 of it: unwritten chunks, not a log",
                ds.size()
            ),
        });
    }
    Ok(())
}

/// A MATLAB char array: u16 UTF-16 code units, or empty (`MATLAB_empty`); at most
/// [`MAX_NAME_UNITS`] units.
fn mat_string(ds: &h5::Dataset) -> Result<String, h5::Error> {
    if ds.attr("MATLAB_empty").is_ok() {
        return Ok(String::new());
    }
    if ds.size() > MAX_NAME_UNITS {
        return Err(format!(
            "a name of {} characters (at most {MAX_NAME_UNITS})",
            ds.size()
        )
        .into());
    }
    let units: Vec<u16> = ds.read_raw()?;
    Ok(String::from_utf16_lossy(&units))
}

/// A MATLAB cellstr: object references to char arrays; at most [`MAX_NAMES`] of them.
fn cellstr(file: &h5::File, ds: &h5::Dataset) -> Result<Vec<String>, h5::Error> {
    if ds.size() > MAX_NAMES {
        return Err(format!("{} names (at most {MAX_NAMES})", ds.size()).into());
    }
    let refs: Vec<ObjectReference1> = ds.read_raw()?;
    refs.iter()
        .map(|r| match file.dereference(r)? {
            h5::ReferencedObject::Dataset(d) => mat_string(&d),
            _ => Err("a cell reference does not point to a dataset".into()),
        })
        .collect()
}

/// Opens a channel group and finds `joints` in it; `Ok(None)` when the channel is absent.
fn channel(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    name: &str,
    joints: &[String],
) -> Result<Option<(Channel, Vec<String>, usize)>, LogsError> {
    if !root.link_exists(name.split('/').next().unwrap_or(name)) {
        return Ok(None);
    }
    let Ok(g) = root.group(name) else {
        return Ok(None);
    };
    if !g.link_exists("data") {
        return Ok(None); // an empty struct: no data at save time
    }
    let e = |what: &str, err: h5::Error| h5err(path, &format!("{name}/{what}"), err);
    let data = g.dataset("data").map_err(|x| e("data", x))?;
    let names_ds = g
        .dataset("elements_names")
        .map_err(|x| e("elements_names", x))?;
    let names = cellstr(file, &names_ds).map_err(|x| e("elements_names", x))?;
    let shape = data.shape();
    if shape.len() != 3 || shape[1] != 1 || shape[2] != names.len() {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: format!(
                "{name}/data has shape {shape:?}; expected (N, 1, {}) for {} elements_names",
                names.len(),
                names.len()
            ),
        });
    }
    check_stored(path, &format!("{name}/data"), &data)?;
    let n = shape[0];
    let mut cols = Vec::with_capacity(joints.len());
    for joint in joints {
        let Some(col) = names.iter().position(|x| x == joint) else {
            return Err(LogsError::JointNotFound {
                path: path.display().to_string(),
                joint: joint.to_string(),
                available: format!("({name}) {}", names.join(", ")),
            });
        };
        cols.push(col);
    }
    Ok(Some((Channel { data, cols }, names, n)))
}

fn timestamps(
    path: &Path,
    root: &h5::Group,
    name: &str,
    n: usize,
) -> Result<h5::Dataset, LogsError> {
    let ts = root
        .group(name)
        .and_then(|g| g.dataset("timestamps"))
        .map_err(|e| h5err(path, &format!("{name}/timestamps"), e))?;
    let shape = ts.shape();
    if shape.first() != Some(&n) || shape.iter().product::<usize>() != n {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: format!("{name}/timestamps has shape {shape:?}; expected ({n}, 1)"),
        });
    }
    check_stored(path, &format!("{name}/timestamps"), &ts)?;
    Ok(ts)
}

fn read_ts(path: &Path, ts: &h5::Dataset, a: usize, b: usize) -> Result<Vec<f64>, LogsError> {
    let v: ndarray::Array1<f64> = if ts.ndim() == 2 {
        ts.read_slice_1d(ndarray::s![a..b, 0])
    } else {
        ts.read_slice_1d(ndarray::s![a..b])
    }
    .map_err(|e| h5err(path, "timestamps", e))?;
    Ok(v.to_vec())
}

/// Reads one joint from a YARP robot logger `.mat` file into a run named after the file stem. The
/// joint's name is in the report's `sources["joint"]`.
pub fn read(path: &Path, spec: &MatSpec, progress: Progress) -> Result<ImportedRun, LogsError> {
    read_streamed(path, spec, &MatState::default(), progress, None)
}

/// [`read`] with the whole-body state's further channels `state`.
pub fn read_state(
    path: &Path,
    spec: &MatSpec,
    state: &MatState,
    progress: Progress,
) -> Result<ImportedRun, LogsError> {
    read_streamed(path, spec, state, progress, None)
}

/// [`read`], handing the rows to `stream` in blocks as they are read (hyperslabs of the sink's block
/// size, at most 65 536 ticks) instead of holding them (`None`: held; see [`crate::BlockSink`]):
/// the returned run then has the report and no rows.
pub fn read_streamed(
    path: &Path,
    spec: &MatSpec,
    extra: &MatState,
    progress: Progress,
    stream: Option<crate::BlockSink<'_>>,
) -> Result<ImportedRun, LogsError> {
    let p = path.display().to_string();
    check_mat_header(path)?;
    let file = h5::File::open(path).map_err(|e| h5err(path, "HDF5", e))?;
    let root = file.group(ROOT).map_err(|_| LogsError::Format {
        path: p.clone(),
        msg: format!(
            "no `/{ROOT}` struct (not a YARP robot logger file); top level: {}",
            file.member_names().unwrap_or_default().join(", ")
        ),
    })?;
    let joints = select_joints(path, &file, &root, spec)?;
    let JointChannels {
        chans: joint_chans,
        n_ticks,
        mut notes,
        sources,
        mut state,
    } = joint_channels(path, &file, &root, spec, &joints)?;
    let n = n_ticks.unwrap_or(0);
    if n == 0 {
        return Err(LogsError::Empty {
            path: p,
            what: "joints_state/positions has no samples".into(),
        });
    }
    let ts = timestamps(path, &root, "joints_state/positions", n)?;
    let mut chans = open_lanes(path, &root, &ts, n, joint_chans)?;
    let mut extras = match state.as_mut() {
        Some((layout, cols)) => {
            state_extras(path, &file, &root, extra, n, layout, cols, &mut notes)?
        }
        None => no_state_extras(extra)?,
    };
    // Chunk spans from the desired-current stream.
    let spans = desired_spans(path, &root, spec.desired_gap_s, &mut notes)?;
    let roles: Vec<Role> = chans.iter().map(|c| c.0).collect();
    let mut map = RoleMap::si(&roles);
    for &r in &spec.negate {
        map.negate(r)?;
    }
    // Map order is time then `roles` in order: the same as `chans`.
    let state_cols = state.as_ref().map(|s| s.1.clone()).unwrap_or_default();
    let positions = chans.first().and_then(|c| match &c.1 {
        Lane::Ticks(ch) => Some(ch.data.clone()),
        Lane::Own(_) => None,
    });
    // Why a tick in a lane's gap is skipped, per lane.
    let gap_reasons: Vec<String> = chans.iter().map(|(_, l)| l.gap_reason()).collect();
    // Hyperslabs of at most BLOCK ticks; streamed, of the sink's block size.
    let block = stream
        .as_ref()
        .map_or(BLOCK, |s| s.block_rows.clamp(1, BLOCK));
    let mut b = RunBuilder::with_joints(map, joints.clone(), state.map(|s| s.0), &p, "mat")
        .streaming(stream);
    let rep = b.report_mut();
    rep.sources.insert("joint".into(), joints.join(", "));
    rep.sources.insert(
        "time".into(),
        "joints_state/positions/timestamps - t0".into(),
    );
    for (r, s) in sources {
        rep.sources.insert(r.name().into(), s);
    }
    rep.notes.extend(notes);
    let mut rows = RowChunker::new(spans);
    let mut a = 0;
    while a < n {
        let e = (a + block).min(n);
        let t = read_ts(path, &ts, a, e)?;
        let (mut cols, gap) = read_lane_block(path, &mut chans, joints.len(), &t, a, e)?;
        if let (Some(pos), false) = (&positions, state_cols.is_empty()) {
            push_state_block(path, pos, &state_cols, &mut extras, a, e, &mut cols)?;
        }
        rows.push_block(&mut b, &mut chans, &gap_reasons, &t, &gap, &cols, a)?;
        a = e;
        progress(a as u64, n as u64);
    }
    let rep = b.report_mut();
    for (_, lane) in &chans {
        if let Lane::Own(al) = lane {
            al.say(&mut rep.notes, &mut rep.warnings);
        }
    }
    if let Some(t0) = rows.t0 {
        rep.notes
            .push(format!("time origin t0 = {t0:.6} s since the epoch"));
    }
    let name = path
        .file_stem()
        .map_or_else(|| "run".to_string(), |s| s.to_string_lossy().into_owned());
    b.finish(&p, name)
}

/// Checks that `path` is a non-empty file starting with the MATLAB v7.3 header (an HDF5 file
/// saved by MATLAB with `-v7.3`).
fn check_mat_header(path: &Path) -> Result<(), LogsError> {
    let mut f = open_regular(path)?;
    let total = f.metadata().map(|m| m.len()).unwrap_or(0);
    if total == 0 {
        return Err(LogsError::Empty {
            path: path.display().to_string(),
            what: "empty file".into(),
        });
    }
    let mut head = [0u8; 128];
    let got = f.read(&mut head).map_err(|e| LogsError::io(path, e))?;
    if got < 19 || !head.starts_with(b"MATLAB 7.3 MAT-file") {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: "not a MATLAB v7.3 file (no `MATLAB 7.3 MAT-file` header); save with -v7.3".into(),
        });
    }
    Ok(())
}

/// The joints to label: every joint of the positions the URDF knows (`spec.all_joints`), those
/// asked for, or else the one the desired-current channel names.
fn select_joints(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    spec: &MatSpec,
) -> Result<Vec<String>, LogsError> {
    let desired_joint = match root
        .group(DESIRED)
        .and_then(|g| g.dataset("elements_names"))
    {
        Ok(ds) => cellstr(file, &ds)
            .map_err(|e| h5err(path, DESIRED, e))?
            .into_iter()
            .next(),
        Err(_) => None,
    };
    Ok(match (spec.joints.is_empty(), &desired_joint) {
        _ if spec.all_joints => {
            let urdf = spec.state_joints.as_ref().ok_or_else(|| {
                LogsError::Usage(
                    "all joints: the whole-body state (the URDF's joint names) is needed".into(),
                )
            })?;
            let g = root
                .group("joints_state/positions")
                .and_then(|g| g.dataset("elements_names"))
                .map_err(|e| h5err(path, "joints_state/positions/elements_names", e))?;
            let mut v: Vec<String> = cellstr(file, &g)
                .map_err(|e| h5err(path, "joints_state/positions/elements_names", e))?
                .into_iter()
                .filter(|n| urdf.contains(n))
                .collect();
            v.dedup();
            v
        }
        (false, _) => spec.joints.clone(),
        (true, Some(j)) => vec![j.clone()],
        (true, None) => {
            return Err(LogsError::Usage(format!(
                "{}: no --joint and no `{DESIRED}` channel naming the moving joint",
                path.display()
            )));
        }
    })
}

/// The joint channels as lanes: the positions on their own ticks, every other channel on its own
/// timestamps, aligned onto the positions' ticks `ts` (`n` of them).
fn open_lanes(
    path: &Path,
    root: &h5::Group,
    ts: &h5::Dataset,
    n: usize,
    joint_chans: Vec<(Role, Channel, usize, String)>,
) -> Result<Vec<(Role, Lane)>, LogsError> {
    let ref_step_s = median_step(path, ts, n)?.unwrap_or(f64::INFINITY);
    let mut chans: Vec<(Role, Lane)> = Vec::with_capacity(joint_chans.len());
    for (role, ch, len, name) in joint_chans {
        chans.push(if role == Role::S {
            (role, Lane::Ticks(ch))
        } else {
            (
                role,
                Lane::Own(Aligned::open(path, root, &name, ch, len, ref_step_s)?),
            )
        });
    }
    Ok(chans)
}

/// Without a whole-body state: none of its further channels may be asked for.
fn no_state_extras(extra: &MatState) -> Result<StateExtras, LogsError> {
    if extra.base_orientation.is_some() || !extra.wrenches.is_empty() || extra.logged_derivatives {
        return Err(LogsError::Usage(
            "a base orientation, a wrench or logged derivatives enter the whole-body state, which only the \
             current label with a URDF reads"
                .into(),
        ));
    }
    Ok(StateExtras::default())
}

/// Per lane, per joint: the values of ticks `a..e` (stamped `t`), joint-major (every role of the
/// first joint, then the next joint's: the row order); and per tick, the first lane without a
/// value there.
#[allow(clippy::type_complexity)]
fn read_lane_block(
    path: &Path,
    chans: &mut [(Role, Lane)],
    n_joints: usize,
    t: &[f64],
    a: usize,
    e: usize,
) -> Result<(Vec<ndarray::Array1<f64>>, Vec<Option<usize>>), LogsError> {
    let mut gap: Vec<Option<usize>> = vec![None; e - a];
    let mut per_chan: Vec<Vec<ndarray::Array1<f64>>> = Vec::with_capacity(chans.len());
    for (ci, (role, lane)) in chans.iter_mut().enumerate() {
        per_chan.push(match lane {
            Lane::Ticks(ch) => (0..n_joints)
                .map(|j| {
                    ch.data
                        .read_slice_1d(ndarray::s![a..e, 0, ch.cols[j]])
                        .map_err(|x| h5err(path, &format!("{role} data"), x))
                })
                .collect::<Result<_, _>>()?,
            Lane::Own(al) => {
                let mut v = vec![ndarray::Array1::from_elem(e - a, f64::NAN); n_joints];
                let mut at = vec![f64::NAN; n_joints];
                for (k, &tk) in t.iter().enumerate() {
                    if al.at(path, tk, &mut at)? {
                        for (vj, x) in v.iter_mut().zip(&at) {
                            vj[k] = *x;
                        }
                    } else if gap[k].is_none() {
                        gap[k] = Some(ci);
                    }
                }
                v
            }
        });
    }
    let mut cols = Vec::with_capacity(chans.len() * n_joints);
    for j in 0..n_joints {
        for c in &mut per_chan {
            cols.push(std::mem::take(&mut c[j]));
        }
    }
    Ok((cols, gap))
}

/// Appends the whole-body state's columns of ticks `a..e` to `cols`: per state joint its position
/// (and the logged velocity and acceleration), then the base quaternion and the wrenches.
fn push_state_block(
    path: &Path,
    positions: &h5::Dataset,
    state_cols: &[usize],
    extras: &mut StateExtras,
    a: usize,
    e: usize,
    cols: &mut Vec<ndarray::Array1<f64>>,
) -> Result<(), LogsError> {
    let all: ndarray::Array2<f64> = positions
        .read_slice_2d(ndarray::s![a..e, 0, ..])
        .map_err(|x| h5err(path, "joints_state/positions data", x))?;
    let vel = extras
        .qdot
        .as_ref()
        .map(|c| c.block(path, a, e))
        .transpose()?;
    let acc = extras
        .qddot
        .as_ref()
        .map(|c| c.block(path, a, e))
        .transpose()?;
    for &c in state_cols {
        cols.push(all.column(c).to_owned());
        for d in [&vel, &acc].into_iter().flatten() {
            cols.push(d.column(c).to_owned());
        }
    }
    extras.push_block(path, a, e, cols)
}

/// Hands the read ticks to the run as rows with their chunk ids: skips the ticks outside the
/// desired-current stream's spans and those in a lane's gap, and closes a chunk at each gap.
struct RowChunker {
    /// The desired-current stream's spans (none: one chunk but for the gaps).
    spans: Vec<(f64, f64)>,
    /// The span the last tick fell in or before.
    span_i: usize,
    /// Chunks closed by a channel's gap so far.
    gap_breaks: u32,
    /// Whether the previous tick was in a gap.
    in_gap: bool,
    /// The first row's timestamp (the time origin).
    t0: Option<f64>,
}

impl RowChunker {
    fn new(spans: Vec<(f64, f64)>) -> Self {
        Self {
            spans,
            span_i: 0,
            gap_breaks: 0,
            in_gap: false,
            t0: None,
        }
    }

    /// Pushes the block's ticks `t` (from tick `a`), their columns `cols` and lane gaps `gap`.
    #[allow(clippy::too_many_arguments)]
    fn push_block(
        &mut self,
        b: &mut RunBuilder<'_>,
        chans: &mut [(Role, Lane)],
        gap_reasons: &[String],
        t: &[f64],
        gap: &[Option<usize>],
        cols: &[ndarray::Array1<f64>],
        a: usize,
    ) -> Result<(), LogsError> {
        let spans = &self.spans;
        for (k, &tk) in t.iter().enumerate() {
            let mut chunk = 0u32;
            if !spans.is_empty() {
                while self.span_i < spans.len() && tk > spans[self.span_i].1 {
                    self.span_i += 1;
                }
                if self.span_i >= spans.len() || tk < spans[self.span_i].0 {
                    b.skip("outside the desired-current stream");
                    continue;
                }
                chunk = self.span_i as u32;
            }
            if let Some(ci) = gap[k] {
                b.skip(&gap_reasons[ci]);
                if let Lane::Own(al) = &mut chans[ci].1 {
                    al.dropped += 1;
                }
                self.in_gap = true;
                continue;
            }
            // A channel's gap closes the chunk: the pipeline never interpolates across it.
            if std::mem::take(&mut self.in_gap) && self.t0.is_some() {
                self.gap_breaks += 1;
            }
            chunk += self.gap_breaks;
            let origin = *self.t0.get_or_insert(tk);
            let row = b.row_mut();
            row[0] = tk - origin;
            for (j, c) in cols.iter().enumerate() {
                row[j + 1] = c[k];
            }
            b.push(|| format!("tick {}", a + k), chunk)?;
        }
        Ok(())
    }
}

/// How a joint channel's samples meet the positions' ticks.
enum Lane {
    /// The positions themselves: sample k is tick k.
    Ticks(Channel),
    /// Any other channel: on its own timestamps, aligned.
    Own(Aligned),
}

impl Lane {
    /// The skip reason of a tick in the lane's gap (the positions have none).
    fn gap_reason(&self) -> String {
        match self {
            Lane::Own(al) => format!("in a gap of {}", al.name),
            Lane::Ticks(_) => String::new(),
        }
    }
}

/// The channels of the labelled joints' signals, in the row's role order (the position first).
#[derive(Default)]
struct JointChannels {
    /// Role, channel, its sample count and its name under the root.
    chans: Vec<(Role, Channel, usize, String)>,
    /// The position channel's ticks.
    n_ticks: Option<usize>,
    notes: Vec<String>,
    /// Each role's channel and elements, for the report.
    sources: Vec<(Role, String)>,
    /// The whole-body state's layout and the position columns it reads (with a URDF).
    state: Option<(crate::StateLayout, Vec<usize>)>,
}

/// Finds the position, motor position, velocity, current and temperature channels of `joints`
/// (each with its own sample count: all but the positions are aligned by their timestamps) and,
/// with the URDF's names, the whole-body state's joints.
fn joint_channels(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    spec: &MatSpec,
    joints: &[String],
) -> Result<JointChannels, LogsError> {
    let wanted: [(Role, &str); 5] = [
        (Role::S, "joints_state/positions"),
        (Role::Theta, "motors_state/positions"),
        (Role::Omega, "motors_state/velocities"),
        (Role::Current, "motors_state/currents"),
        (Role::Temperature, "motors_state/temperatures"),
    ];
    let mut out = JointChannels::default();
    // The velocity and acceleration columns are those of the positions (checked below).
    for (role, name) in wanted {
        match channel(path, file, root, name, joints)? {
            Some((ch, names, n)) => {
                if role == Role::S
                    && let Some(urdf) = &spec.state_joints
                {
                    let mut st_names = Vec::new();
                    let mut st_cols = Vec::new();
                    let mut unknown = Vec::new();
                    // Every joint is kept (the pipeline lists the URDF's missing ones).
                    for (k, nm) in names.iter().enumerate() {
                        if !urdf.contains(nm) {
                            unknown.push(nm.as_str());
                        }
                        if !st_names.contains(nm) {
                            st_names.push(nm.clone());
                            st_cols.push(k);
                        }
                    }
                    out.notes.push(format!(
                        "whole-body state: {} joints of {name}",
                        st_names.len()
                    ));
                    if !unknown.is_empty() {
                        out.notes.push(format!(
                            "joints of {name} that the URDF lacks (not used): {}",
                            unknown.join(", ")
                        ));
                    }
                    out.state = Some((crate::StateLayout::positions(st_names), st_cols));
                }
                if role == Role::S {
                    out.n_ticks = Some(n);
                }
                out.sources.push((
                    role,
                    format!(
                        "{name} (element {})",
                        ch.cols
                            .iter()
                            .map(usize::to_string)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
                out.chans.push((role, ch, n, name.to_string()));
            }
            None if role == Role::S => {
                return Err(LogsError::Format {
                    path: path.display().to_string(),
                    msg: format!("no `{ROOT}/joints_state/positions` channel (the joint position)"),
                });
            }
            None => out.notes.push(format!("{name}: absent")),
        }
    }
    Ok(out)
}
/// The spans of the desired-current stream's stamps between gaps longer than `gap_s` [s] (the
/// chunks: the robot ticks outside them are skipped); none without the stream (noted).
fn desired_spans(
    path: &Path,
    root: &h5::Group,
    gap_s: f64,
    notes: &mut Vec<String>,
) -> Result<Vec<(f64, f64)>, LogsError> {
    let mut spans: Vec<(f64, f64)> = Vec::new();
    if let Ok(g) = root.group(DESIRED)
        && let Ok(dts) = g.dataset("timestamps")
    {
        check_stored(path, &format!("{DESIRED}/timestamps"), &dts)?;
        let m = dts.shape().first().copied().unwrap_or(0);
        let mut a = 0;
        while a < m {
            let b = (a + BLOCK).min(m);
            for t in read_ts(path, &dts, a, b)? {
                if !t.is_finite() {
                    continue;
                }
                match spans.last_mut() {
                    Some(s) if t - s.1 <= gap_s && t >= s.1 => s.1 = t,
                    _ => spans.push((t, t)),
                }
            }
            a = b;
        }
        notes.push(format!(
            "chunks: {} spans of {DESIRED} between gaps > {} s",
            spans.len(),
            gap_s
        ));
    } else {
        notes.push(format!(
            "no {DESIRED} channel: chunks from gaps of the robot ticks"
        ));
    }
    Ok(spans)
}

/// The whole-body state's channels beyond the joint positions.
#[derive(Default)]
struct StateExtras {
    /// `joints_state/velocities`, same elements as the positions.
    qdot: Option<StateChannel>,
    /// `joints_state/accelerations`, same elements as the positions.
    qddot: Option<StateChannel>,
    /// The base orientation channel (3: roll, pitch, yaw; 4: quaternion x y z w).
    base: Option<StateChannel>,
    /// One channel of 6 elements per wrench.
    wrenches: Vec<StateChannel>,
    /// The last finite base quaternion handed on (its sign continues).
    last_quat: Option<[f64; 4]>,
}

/// Finds the state's further channels: the joints' velocities and accelerations when asked for and
/// logged with the positions' elements, the base orientation and the wrenches asked for; fills
/// `layout`.
#[allow(clippy::too_many_arguments)]
fn state_extras(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    spec: &MatState,
    n: usize,
    layout: &mut crate::StateLayout,
    cols: &[usize],
    notes: &mut Vec<String>,
) -> Result<StateExtras, LogsError> {
    let mut out = StateExtras::default();
    let pos_names = root
        .group("joints_state/positions")
        .and_then(|g| g.dataset("elements_names"))
        .and_then(|d| cellstr(file, &d))
        .map_err(|e| h5err(path, "joints_state/positions/elements_names", e))?;
    if spec.logged_derivatives {
        (out.qdot, out.qddot) = logged_derivatives(path, file, root, n, &pos_names, notes)?;
    }
    let k = cols.len();
    layout.qdot = vec![out.qdot.is_some(); k];
    layout.qddot = vec![out.qddot.is_some(); k];
    if let Some(b) = &spec.base_orientation {
        let ch = state_channel(
            path,
            file,
            root,
            b,
            n,
            &[&RPY_NAMES, &QUAT_NAMES],
            &[],
            &format!("--base-orientation {b}"),
            notes,
        )?;
        notes.push(format!(
            "base orientation from {b} ({})",
            if ch.width == 3 {
                "roll, pitch, yaw [rad]"
            } else {
                "quaternion x, y, z, w"
            }
        ));
        out.base = Some(ch);
        layout.base_quat = true;
        layout.base_frame = orientation_frame(b);
    }
    for (frame, name) in &spec.wrenches {
        out.wrenches.push(state_channel(
            path,
            file,
            root,
            name,
            n,
            &[&WRENCH_NAMES],
            &[],
            &format!("--wrench {frame}={name}"),
            notes,
        )?);
        notes.push(format!(
            "external wrench at frame `{frame}` from {name} (N, N·m, frame coordinates)"
        ));
        layout.wrenches.push(frame.clone());
    }
    Ok(out)
}

/// The joints' logged velocities and accelerations (`joints_state/velocities`, `.../accelerations`)
/// where they have the elements `pos_names` of the positions (else noted: smoothed from q); an
/// error when neither has.
fn logged_derivatives(
    path: &Path,
    file: &h5::File,
    root: &h5::Group,
    n: usize,
    pos_names: &[String],
    notes: &mut Vec<String>,
) -> Result<(Option<StateChannel>, Option<StateChannel>), LogsError> {
    let (mut qdot, mut qddot) = (None, None);
    for (name, slot) in [
        ("joints_state/velocities", &mut qdot),
        ("joints_state/accelerations", &mut qddot),
    ] {
        let Some(g) = root.group(name).ok().filter(|g| g.link_exists("data")) else {
            notes.push(format!("{name}: absent (smoothed from q)"));
            continue;
        };
        let names = g
            .dataset("elements_names")
            .and_then(|d| cellstr(file, &d))
            .map_err(|e| h5err(path, &format!("{name}/elements_names"), e))?;
        if names != pos_names {
            notes.push(format!(
                "{name}: not the elements of joints_state/positions: not used (smoothed from q)"
            ));
            continue;
        }
        *slot = Some(state_channel(
            path,
            file,
            root,
            name,
            n,
            &[],
            &[pos_names.len()],
            name,
            notes,
        )?);
        notes.push(format!("whole-body state: {name} as logged"));
    }
    if qdot.is_none() && qddot.is_none() {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: "logged derivatives: neither joints_state/velocities nor \
                  joints_state/accelerations has the elements of joints_state/positions"
                .into(),
        });
    }
    Ok((qdot, qddot))
}

impl StateExtras {
    /// Appends rows `a..e` of the base quaternion (4 columns) and the wrenches (6 each) to `cols`.
    /// The quaternion's sign is kept continuous from row to row (q and −q are the same rotation;
    /// a logged quaternion may flip, and interpolating across a flip passes near zero).
    fn push_block(
        &mut self,
        path: &Path,
        a: usize,
        e: usize,
        cols: &mut Vec<ndarray::Array1<f64>>,
    ) -> Result<(), LogsError> {
        if let Some(b) = &self.base {
            let v = b.block(path, a, e)?;
            let mut q: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(e - a));
            for r in v.rows() {
                let x = crate::run::continue_sign(
                    &mut self.last_quat,
                    if b.width == 4 {
                        [r[0], r[1], r[2], r[3]]
                    } else {
                        rpy_to_quat_xyzw(r[0], r[1], r[2])
                    },
                );
                for (c, xc) in q.iter_mut().zip(x) {
                    c.push(xc);
                }
            }
            cols.extend(q.into_iter().map(ndarray::Array1::from));
        }
        for w in &self.wrenches {
            let v = w.block(path, a, e)?;
            cols.extend(v.columns().into_iter().map(|c| c.to_owned()));
        }
        Ok(())
    }
}

/// The frame whose orientation a base-orientation channel holds, as the logger names it: the
/// sensor of `orientations/<sensor>` (the YARP logger names an orientation sensor's channel after
/// it, as the URDF names its frame), the `<frame>` of `frames/<root>/<frame>/orientation`, else
/// the channel's last component.
fn orientation_frame(channel: &str) -> Option<String> {
    let parts: Vec<&str> = channel.split('/').filter(|p| !p.is_empty()).collect();
    let name = match parts.as_slice() {
        [.., frame, "orientation"] => frame,
        [.., last] => last,
        [] => return None,
    };
    Some((*name).to_string())
}
