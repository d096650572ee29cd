//! Any CSV log: columns mapped to [`Role`]s by name, each with a [`Unit`] and an optional sign flip,
//! streamed row by row with the `csv` crate (memory ∝ the mapped columns of the used rows).
//!
//! A field that is empty, `nan` or `inf` is non-finite: its row is counted (per role) and dropped. A
//! field that is not a number at all is an error naming the file, line, column and text. A line
//! longer than 1 MiB or a NUL byte ends the read with an error (a binary or sparse file is not
//! scanned to its end).

use std::io::Read;
use std::path::Path;

use crate::run::RunBuilder;
use crate::{ImportedRun, LogsError, Progress, Role, RoleMap, open_regular};

/// How to read a CSV log.
#[derive(Clone, Debug, PartialEq)]
pub struct CsvSpec {
    /// `(role, column name)`; `time` is required. A name may hold `{joint}`, replaced by each of
    /// [`Self::joints`].
    pub columns: Vec<(Role, String)>,
    /// The labelled joints (empty: one joint, no `{joint}` in any column).
    pub joints: Vec<String>,
    /// Label every joint of the whole-body state that has every mapped column (needs `state`).
    pub all_joints: bool,
    /// The whole-body state to read, if any.
    pub state: Option<CsvState>,
    /// Source units per role (missing: SI).
    pub units: Vec<(Role, crate::Unit)>,
    /// Roles to negate.
    pub negate: Vec<Role>,
    /// Field delimiter.
    pub delimiter: u8,
}

/// The whole-body state of a CSV log: column-name templates with `{joint}` tried for every
/// candidate joint name (the URDF's); the `s`, `sdot` and `sddot` roles' units apply.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CsvState {
    /// Position column template, e.g. `q_{joint}`.
    pub positions: String,
    /// Velocity column template (joints without the column go through the smoother).
    pub velocities: Option<String>,
    /// Acceleration column template.
    pub accelerations: Option<String>,
    /// The joint names to look for (the URDF's movable joints); columns that fit the template for
    /// other names are read too (the pipeline lists them as not in the URDF).
    pub joints: Vec<String>,
    /// Columns of the root link's orientation quaternion `[x, y, z, w]` (absent: fixed base).
    pub base_quat: Option<[String; 4]>,
    /// Measured wrenches applied to the robot: `(frame, column template)`, `{c}` in the template
    /// replaced by `fx, fy, fz` [N] and `mx, my, mz` [N·m] (the frame's coordinates).
    pub wrenches: Vec<(String, String)>,
}

const JOINT: &str = "{joint}";

/// The columns of `header` that fit `template` (`prefix{joint}suffix`), with the joint part.
fn template_matches<'h>(template: &str, header: &'h [String]) -> Vec<(&'h str, usize)> {
    let Some((pre, suf)) = template.split_once(JOINT) else {
        return Vec::new();
    };
    header
        .iter()
        .enumerate()
        .filter(|(_, h)| h.len() > pre.len() + suf.len() && h.starts_with(pre) && h.ends_with(suf))
        .map(|(k, h)| (&h[pre.len()..h.len() - suf.len()], k))
        .collect()
}

impl CsvSpec {
    /// Builds a spec from `ROLE=COLUMN` and `ROLE=UNIT` texts (the command line's `--column` and
    /// `--unit`) and role names to negate; checks roles, units and duplicates.
    pub fn parse(
        columns: &[String],
        units: &[String],
        negate: &[String],
    ) -> Result<Self, LogsError> {
        let split = |s: &str, what: &str| -> Result<(Role, String), LogsError> {
            let (r, v) = s
                .split_once('=')
                .ok_or_else(|| LogsError::Usage(format!("{what} {s:?}: expected ROLE=VALUE")))?;
            Ok((Role::parse(r)?, v.trim().to_string()))
        };
        let mut cols: Vec<(Role, String)> = Vec::new();
        for c in columns {
            let (role, col) = split(c, "--column")?;
            if let Some(prev) = cols.iter().find(|x| x.0 == role) {
                return Err(LogsError::DuplicateRole {
                    role,
                    first: format!("{role}={}", prev.1),
                    second: c.clone(),
                });
            }
            cols.push((role, col));
        }
        if !cols.iter().any(|c| c.0 == Role::Time) {
            return Err(LogsError::Usage(
                "no time column: pass --column time=NAME".into(),
            ));
        }
        let mut us: Vec<(Role, crate::Unit)> = Vec::new();
        for t in units {
            let (role, unit) = split(t, "--unit")?;
            if us.iter().any(|x| x.0 == role) {
                return Err(LogsError::Usage(format!("--unit {role} is given twice")));
            }
            // s, sdot, sddot units also apply to the whole-body state (checked by `read`).
            if !cols.iter().any(|c| c.0 == role)
                && !matches!(role, Role::S | Role::Sdot | Role::Sddot)
            {
                return Err(LogsError::Usage(format!(
                    "--unit {t}: role {role} has no --column"
                )));
            }
            us.push((role, role.parse_unit(&unit)?));
        }
        let neg = negate
            .iter()
            .map(|n| Role::parse(n))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            columns: cols,
            joints: Vec::new(),
            all_joints: false,
            state: None,
            units: us,
            negate: neg,
            delimiter: b',',
        })
    }

    /// The source unit factor of a role (1 for SI).
    fn factor(&self, role: Role) -> f64 {
        self.units
            .iter()
            .find(|u| u.0 == role)
            .map_or(1.0, |u| u.1.factor)
    }

    /// The role map (units and signs) this spec reads into.
    pub fn role_map(&self) -> Result<RoleMap, LogsError> {
        let roles: Vec<Role> = self.columns.iter().map(|c| c.0).collect();
        let mut map = RoleMap::si(&roles);
        for &(r, u) in &self.units {
            if map.has(r) {
                map.set_unit(r, u)?;
            } else {
                let used = self.state.as_ref().is_some_and(|st| match r {
                    Role::S => true,
                    Role::Sdot => st.velocities.is_some(),
                    _ => st.accelerations.is_some(),
                });
                if !used {
                    return Err(LogsError::Usage(format!(
                        "--unit {r}={}: role {r} has no --column{}",
                        u.name,
                        match r {
                            Role::S => " and no --positions",
                            Role::Sdot => " and no --velocities",
                            _ => " and no --accelerations",
                        }
                    )));
                }
            }
        }
        for &r in &self.negate {
            map.negate(r)?;
        }
        Ok(map)
    }
}

/// Longest line accepted [bytes].
const MAX_LINE: usize = 1 << 20;

/// A reader that refuses NUL bytes and lines longer than [`MAX_LINE`], and counts bytes.
struct Guard<R> {
    inner: R,
    since_newline: usize,
    bytes: u64,
    problem: Option<&'static str>,
}

impl<R: Read> Read for Guard<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        for &b in &buf[..n] {
            if b == 0 {
                self.problem = Some("contains a NUL byte: not a text CSV file");
            } else if b == b'\n' {
                self.since_newline = 0;
            } else {
                self.since_newline += 1;
                if self.since_newline > MAX_LINE {
                    self.problem = Some("has a line longer than 1 MiB: not a CSV log");
                }
            }
            if let Some(p) = self.problem {
                return Err(std::io::Error::new(std::io::ErrorKind::InvalidData, p));
            }
        }
        self.bytes += n as u64;
        Ok(n)
    }
}

/// The state layout and the column indices of its values (in [`crate::StateLayout`] row order).
fn state_columns(
    st: &CsvState,
    spec: &CsvSpec,
    header: &[String],
    p: &str,
    notes: &mut Vec<String>,
) -> Result<(crate::StateLayout, Vec<usize>), LogsError> {
    check_joint_templates(st)?;
    let (names, q_idx) = state_position_columns(st, header, p, notes)?;
    let qd = state_derivative_columns(st, header, p, &names, &st.velocities, "--velocities")?;
    let qdd =
        state_derivative_columns(st, header, p, &names, &st.accelerations, "--accelerations")?;
    let mut idx = Vec::new();
    for k in 0..names.len() {
        idx.push(q_idx[k]);
        idx.extend(qd[k]);
        idx.extend(qdd[k]);
    }
    push_base_and_wrench_columns(st, header, p, &mut idx, notes)?;
    notes.push(format!(
        "whole-body state: {} joints from --positions {:?}{}",
        names.len(),
        st.positions,
        if st.base_quat.is_some() {
            ", base orientation from the quaternion columns"
        } else {
            ""
        }
    ));
    let layout = crate::StateLayout {
        qdot: qd.iter().map(Option::is_some).collect(),
        qddot: qdd.iter().map(Option::is_some).collect(),
        factors: [
            spec.factor(Role::S),
            spec.factor(Role::Sdot),
            spec.factor(Role::Sddot),
        ],
        base_quat: st.base_quat.is_some(),
        base_frame: None,
        wrenches: st.wrenches.iter().map(|w| w.0.clone()).collect(),
        names,
    };
    Ok((layout, idx))
}

/// Checks that the position, velocity and acceleration templates hold the joint placeholder.
fn check_joint_templates(st: &CsvState) -> Result<(), LogsError> {
    for (flag, t) in [
        ("--positions", Some(&st.positions)),
        ("--velocities", st.velocities.as_ref()),
        ("--accelerations", st.accelerations.as_ref()),
    ] {
        if let Some(t) = t
            && !t.contains(JOINT)
        {
            return Err(LogsError::Usage(format!(
                "{flag} {t:?}: the template must hold {JOINT} (e.g. `q_{JOINT}`)"
            )));
        }
    }
    Ok(())
}

/// The column of `template` filled with `joint`, if the header has it.
fn template_column(header: &[String], template: &str, joint: &str) -> Option<usize> {
    let name = template.replace(JOINT, joint);
    header.iter().position(|h| *h == name)
}

/// The error of a state template `t` (of `flag`) that matches no column for any URDF joint.
fn no_state_match(st: &CsvState, header: &[String], p: &str, flag: &str, t: &str) -> LogsError {
    LogsError::Format {
        path: p.to_string(),
        msg: format!(
            "{flag} {t:?} matches no column for any of the {} URDF joints ({}); the header has: {}",
            st.joints.len(),
            st.joints
                .iter()
                .take(8)
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
                + if st.joints.len() > 8 { ", …" } else { "" },
            header.join(", ")
        ),
    }
}

/// The state's joint names and their position columns: the URDF's joints with a column of
/// `--positions`, then those of columns fitting it for a name the URDF lacks (kept, and noted).
fn state_position_columns(
    st: &CsvState,
    header: &[String],
    p: &str,
    notes: &mut Vec<String>,
) -> Result<(Vec<String>, Vec<usize>), LogsError> {
    let mut names = Vec::new();
    let mut q_idx = Vec::new();
    for j in &st.joints {
        if let Some(k) = template_column(header, &st.positions, j) {
            names.push(j.clone());
            q_idx.push(k);
        }
    }
    if names.is_empty() {
        return Err(no_state_match(st, header, p, "--positions", &st.positions));
    }
    // Columns that fit the template for a name the URDF lacks: kept, and listed.
    let unknown: Vec<&str> = template_matches(&st.positions, header)
        .into_iter()
        .filter(|(j, _)| !st.joints.iter().any(|n| n == j))
        .map(|(j, k)| {
            names.push(j.to_string());
            q_idx.push(k);
            j
        })
        .collect();
    if !unknown.is_empty() {
        notes.push(format!(
            "columns fitting --positions {:?} whose joint the URDF lacks (not used): {}",
            st.positions,
            unknown.join(", ")
        ));
    }
    Ok((names, q_idx))
}

/// Per state joint, the column of the derivative template `t` (of `flag`), if any; none at all
/// is an error when the template is given.
fn state_derivative_columns(
    st: &CsvState,
    header: &[String],
    p: &str,
    names: &[String],
    t: &Option<String>,
    flag: &str,
) -> Result<Vec<Option<usize>>, LogsError> {
    match t {
        None => Ok(vec![None; names.len()]),
        Some(t) => {
            let v: Vec<Option<usize>> = names
                .iter()
                .map(|j| template_column(header, t, j))
                .collect();
            if v.iter().all(Option::is_none) {
                return Err(no_state_match(st, header, p, flag, t));
            }
            Ok(v)
        }
    }
}

/// Appends the base quaternion's columns and every wrench's six columns to `idx`.
fn push_base_and_wrench_columns(
    st: &CsvState,
    header: &[String],
    p: &str,
    idx: &mut Vec<usize>,
    notes: &mut Vec<String>,
) -> Result<(), LogsError> {
    if let Some(cols) = &st.base_quat {
        for c in cols {
            idx.push(header.iter().position(|h| h == c).ok_or_else(|| {
                LogsError::MissingOptionColumn {
                    path: p.to_string(),
                    column: c.clone(),
                    option: "--base-quat".into(),
                    header: header.join(", "),
                }
            })?);
        }
    }
    for (frame, template) in &st.wrenches {
        if !template.contains("{c}") {
            return Err(LogsError::Usage(format!(
                "--wrench {frame}={template}: the column template must hold {{c}} (replaced by {})",
                crate::WRENCH_COMPONENTS.join(", ")
            )));
        }
        for c in crate::WRENCH_COMPONENTS {
            let name = template.replace("{c}", c);
            idx.push(header.iter().position(|h| *h == name).ok_or_else(|| {
                LogsError::MissingOptionColumn {
                    path: p.to_string(),
                    column: name.clone(),
                    option: format!("--wrench {frame}={template}"),
                    header: header.join(", "),
                }
            })?);
        }
        notes.push(format!(
            "external wrench at frame `{frame}` from columns {template:?} (N, N·m, frame coordinates)"
        ));
    }
    Ok(())
}

/// Reads one CSV log into a run named after the file stem.
pub fn read(path: &Path, spec: &CsvSpec, progress: Progress) -> Result<ImportedRun, LogsError> {
    read_streamed(path, spec, progress, None)
}

/// The CSV reader of `path` (through the [`Guard`]) with its trimmed header and the file's size.
type OpenedCsv = (
    csv::Reader<Guard<std::io::BufReader<std::fs::File>>>,
    Vec<String>,
    u64,
);

/// [`read`], handing the rows to `stream` in blocks as they are read instead of holding them
/// (`None`: held; see [`crate::BlockSink`]): the returned run then has the report and no rows.
pub fn read_streamed(
    path: &Path,
    spec: &CsvSpec,
    progress: Progress,
    stream: Option<crate::BlockSink<'_>>,
) -> Result<ImportedRun, LogsError> {
    let p = path.display().to_string();
    let (mut r, header, total) = open_csv(path, spec)?;
    let map = spec.role_map()?;
    let mut notes = Vec::new();
    let state = match &spec.state {
        Some(st) => Some(state_columns(st, spec, &header, &p, &mut notes)?),
        None => None,
    };
    let joints = select_joints(spec, state.as_ref().map(|s| &s.0), &header, &p, &mut notes)?;
    let mut idx = role_columns(spec, &map, &header, &p, &joints)?;
    let layout = state.map(|(layout, state_idx)| {
        idx.extend(state_idx);
        layout
    });
    let mut b = RunBuilder::with_joints(map, joints, layout, &p, "csv").streaming(stream);
    for (role, col) in &spec.columns {
        b.report_mut()
            .sources
            .insert(role.name().to_string(), format!("column `{col}`"));
    }
    b.report_mut().notes.extend(notes);
    read_rows(path, &mut r, &mut b, &idx, &header, &mut *progress, total)?;
    progress(total, total);
    let name = path
        .file_stem()
        .map_or_else(|| "run".to_string(), |s| s.to_string_lossy().into_owned());
    b.finish(&p, name)
}

/// Opens the non-empty CSV log `path` and reads its header line.
fn open_csv(path: &Path, spec: &CsvSpec) -> Result<OpenedCsv, LogsError> {
    let p = path.display().to_string();
    let file = open_regular(path)?;
    let total = file.metadata().map(|m| m.len()).unwrap_or(0);
    if total == 0 {
        return Err(LogsError::Empty {
            path: p,
            what: "empty file".into(),
        });
    }
    let guard = Guard {
        inner: std::io::BufReader::with_capacity(1 << 16, file),
        since_newline: 0,
        bytes: 0,
        problem: None,
    };
    let mut r = csv::ReaderBuilder::new()
        .delimiter(spec.delimiter)
        .flexible(true)
        .comment(Some(b'#'))
        .from_reader(guard);
    let header: Vec<String> = r
        .headers()
        .map_err(|e| LogsError::io(path, e))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    if header.is_empty() || header.iter().all(String::is_empty) {
        return Err(LogsError::Empty {
            path: p,
            what: "no header line".into(),
        });
    }
    Ok((r, header, total))
}

/// The index of the header's one column `col` holding `role`: absent or repeated is an error.
fn find_column(p: &str, header: &[String], col: &str, role: Role) -> Result<usize, LogsError> {
    let k = header
        .iter()
        .position(|h| h == col)
        .ok_or_else(|| LogsError::MissingColumn {
            path: p.to_string(),
            column: col.to_string(),
            role,
            header: header.join(", "),
        })?;
    let same: Vec<String> = (0..header.len())
        .filter(|&k| header[k] == *col)
        .map(|k| (k + 1).to_string())
        .collect();
    if same.len() > 1 {
        return Err(LogsError::Format {
            path: p.to_string(),
            msg: format!(
                "column `{col}` (role {role}) is in the header {} times (columns {}): which \
                 one holds it is ambiguous; rename the others",
                same.len(),
                same.join(", ")
            ),
        });
    }
    Ok(k)
}

/// The joints to label: with `spec.all_joints` every state joint of the URDF with every mapped
/// column (those lacking one noted), else those named, else one unnamed joint (the columns then
/// must not be templates).
fn select_joints(
    spec: &CsvSpec,
    state: Option<&crate::StateLayout>,
    header: &[String],
    p: &str,
    notes: &mut Vec<String>,
) -> Result<Vec<String>, LogsError> {
    let templated = spec.columns.iter().any(|c| c.1.contains(JOINT));
    if !spec.all_joints {
        if spec.joints.is_empty() {
            if templated {
                return Err(LogsError::Usage(format!(
                    "a --column holds {JOINT} but no joint is named to replace it"
                )));
            }
            return Ok(vec![String::new()]);
        }
        return Ok(spec.joints.clone());
    }
    let Some(layout) = state else {
        return Err(LogsError::Usage(
            "all joints: the whole-body state (--positions) is needed".into(),
        ));
    };
    // Every state joint with every mapped column.
    let mut lacking = Vec::new();
    let urdf = spec
        .state
        .as_ref()
        .map(|st| st.joints.as_slice())
        .unwrap_or_default();
    let v: Vec<String> = layout
        .names
        .iter()
        .filter(|j| urdf.contains(j))
        .filter(|j| {
            let ok = spec
                .columns
                .iter()
                .all(|c| header.iter().any(|h| *h == c.1.replace(JOINT, j)));
            if !ok {
                lacking.push(j.as_str());
            }
            ok
        })
        .cloned()
        .collect();
    if !lacking.is_empty() {
        notes.push(format!(
            "not labelled (a mapped column is missing): {}",
            lacking.join(", ")
        ));
    }
    if v.is_empty() {
        return Err(LogsError::Format {
            path: p.to_string(),
            msg: format!(
                "no joint of the state has every mapped column ({}); the header has: {}",
                spec.columns
                    .iter()
                    .map(|c| c.1.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                header.join(", ")
            ),
        });
    }
    Ok(v)
}

/// The column indices of the row: the time column, then per joint every mapped role's column.
fn role_columns(
    spec: &CsvSpec,
    map: &RoleMap,
    header: &[String],
    p: &str,
    joints: &[String],
) -> Result<Vec<usize>, LogsError> {
    let mut idx = Vec::new();
    let column_of = |role: Role| -> Result<&String, LogsError> {
        Ok(&spec
            .columns
            .iter()
            .find(|c| c.0 == role)
            .ok_or_else(|| LogsError::Usage(format!("role {role} has no column")))?
            .1)
    };
    let time_col = column_of(Role::Time)?;
    if time_col.contains(JOINT) {
        return Err(LogsError::Usage(format!(
            "--column time={time_col}: the time column is shared by every joint, it cannot hold {JOINT}"
        )));
    }
    idx.push(find_column(p, header, time_col, Role::Time)?);
    for j in joints {
        for role in map.roles().skip(1) {
            idx.push(find_column(
                p,
                header,
                &column_of(role)?.replace(JOINT, j),
                role,
            )?);
        }
    }
    Ok(idx)
}

/// Reads every record of `r` into the run: the columns `idx` parsed as numbers (an empty field is
/// NaN, any other non-number an error naming the line and column).
fn read_rows(
    path: &Path,
    r: &mut csv::Reader<Guard<std::io::BufReader<std::fs::File>>>,
    b: &mut RunBuilder<'_>,
    idx: &[usize],
    header: &[String],
    progress: Progress,
    total: u64,
) -> Result<(), LogsError> {
    let mut rec = csv::ByteRecord::new();
    let mut line: u64 = 1;
    let mut rows = 0u64;
    loop {
        match r.read_byte_record(&mut rec) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(LogsError::io(path, format!("line {}: {e}", line + 1))),
        }
        line = rec.position().map_or(line + 1, |pos| pos.line());
        let row = b.row_mut();
        for (k, &j) in idx.iter().enumerate() {
            let raw = rec.get(j).unwrap_or(b"");
            let text = std::str::from_utf8(raw).unwrap_or("\u{fffd}").trim();
            row[k] = if text.is_empty() {
                f64::NAN
            } else {
                match text.parse::<f64>() {
                    Ok(v) => v,
                    Err(_) => {
                        return Err(LogsError::Parse {
                            path: path.display().to_string(),
                            line,
                            column: header[j].clone(),
                            value: text.chars().take(64).collect(),
                        });
                    }
                }
            };
        }
        b.push(|| format!("line {line}"), 0)?;
        rows += 1;
        if rows.is_multiple_of(65536) {
            progress(r.get_ref().bytes, total);
        }
    }
    Ok(())
}
