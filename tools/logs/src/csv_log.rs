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
    /// `(role, column name)`; `time` is required.
    pub columns: Vec<(Role, String)>,
    /// Source units per role (missing: SI).
    pub units: Vec<(Role, crate::Unit)>,
    /// Roles to negate.
    pub negate: Vec<Role>,
    /// Field delimiter.
    pub delimiter: u8,
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
            if !cols.iter().any(|c| c.0 == role) {
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
            units: us,
            negate: neg,
            delimiter: b',',
        })
    }

    /// The role map (units and signs) this spec reads into.
    pub fn role_map(&self) -> Result<RoleMap, LogsError> {
        let roles: Vec<Role> = self.columns.iter().map(|c| c.0).collect();
        let mut map = RoleMap::si(&roles);
        for &(r, u) in &self.units {
            map.set_unit(r, u)?;
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

/// Reads one CSV log into a run named after the file stem.
pub fn read(path: &Path, spec: &CsvSpec, progress: Progress) -> Result<ImportedRun, LogsError> {
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
    let map = spec.role_map()?;
    let mut idx = Vec::with_capacity(map.len());
    for role in map.roles() {
        let col = &spec
            .columns
            .iter()
            .find(|c| c.0 == role)
            .ok_or_else(|| LogsError::Usage(format!("role {role} has no column")))?
            .1;
        let j = header
            .iter()
            .position(|h| h == col)
            .ok_or_else(|| LogsError::MissingColumn {
                path: p.clone(),
                column: col.clone(),
                role,
                header: header.join(", "),
            })?;
        let same: Vec<String> = (0..header.len())
            .filter(|&k| header[k] == *col)
            .map(|k| (k + 1).to_string())
            .collect();
        if same.len() > 1 {
            return Err(LogsError::Format {
                path: p,
                msg: format!(
                    "column `{col}` (role {role}) is in the header {} times (columns {}): which \
                     one holds it is ambiguous; rename the others",
                    same.len(),
                    same.join(", ")
                ),
            });
        }
        idx.push(j);
    }
    let mut b = RunBuilder::new(map, &p, "csv");
    for (role, col) in &spec.columns {
        b.report_mut()
            .sources
            .insert(role.name().to_string(), format!("column `{col}`"));
    }
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
                            path: p,
                            line,
                            column: header[j].clone(),
                            value: text.chars().take(64).collect(),
                        });
                    }
                }
            };
        }
        b.push(|| format!("line {line}"), 0);
        rows += 1;
        if rows.is_multiple_of(65536) {
            progress(r.get_ref().bytes, total);
        }
    }
    progress(total, total);
    let name = path
        .file_stem()
        .map_or_else(|| "run".to_string(), |s| s.to_string_lossy().into_owned());
    b.finish(&p, name)
}
