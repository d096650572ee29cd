//! ROS 2 MCAP bags: `sensor_msgs/msg/JointState` messages on one topic, one joint picked by name in
//! every message (the name order may change between messages), streamed with the `mcap` crate's
//! sans-io linear reader (memory ∝ one chunk of the file plus the joint's samples). The reader is fed
//! at most 1 MiB per read; chunks are split and decompressed here; only schema, channel and message
//! records are parsed, each after its length fields are checked against the record, so a corrupt
//! length costs an error, never an allocation of what it claims.
//!
//! Fields → roles: `position` → s [rad], `velocity` → ṡ [rad/s], `effort` → a torque role chosen by
//! the caller (`tau_joint` by default: a torque-sensed arm's measured joint torque) [Nm]; an empty
//! array means "not measured" for the whole message. Time is `header.stamp` minus the first
//! message's stamp.
//!
//! The CDR payload is decoded by hand ([`decode_joint_state`]): the message is five fields of
//! primitives, strings and sequences, every read is bounds-checked, and the serde-based `cdr` crate
//! has had no release since 2021 — a dependency for twenty lines was not worth it.
//!
//! The whole-body state ([`read_state`]) can also take the root link's orientation from a
//! `sensor_msgs/msg/Imu` topic and measured wrenches from `geometry_msgs/msg/WrenchStamped` topics
//! ([`McapState`]), each sampled and held onto the `JointState` rows in the bag's order.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use mcap::records::{Record, op};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

pub use crate::mcap_cdr::{
    JointState, decode_imu, decode_imu_orientation, decode_joint_state, decode_wrench,
};
pub use crate::mcap_state::McapState;
use crate::mcap_state::StateTopics;
use crate::run::RunBuilder;
use crate::{ImportedRun, LogsError, Progress, Role, RoleMap, open_regular};

/// How to read an MCAP bag.
#[derive(Clone, Debug, PartialEq)]
pub struct McapSpec {
    /// Topic of the `JointState` messages.
    pub topic: String,
    /// Names of the labelled joints (one or more), matched in every message.
    pub joints: Vec<String>,
    /// Label every joint of the whole-body state instead of `joints` (needs `state_joints`).
    pub all_joints: bool,
    /// Read the whole-body state: every name of the first message's `name` array, with `position`
    /// and, when every message has it, `velocity`; the names not in this list (the URDF's joints)
    /// are listed in the report.
    pub state_joints: Option<Vec<String>>,
    /// Role of the `effort` field (`None`: ignore it); one of [`EFFORT_ROLES`] ([`read`] refuses
    /// another).
    pub effort_role: Option<Role>,
    /// Roles to negate.
    pub negate: Vec<Role>,
}

/// The roles the `effort` field can be read as (a torque or a motor current).
pub const EFFORT_ROLES: [Role; 4] = [Role::TauJoint, Role::TauMotor, Role::TauF, Role::Current];

/// Parses the `effort` field's role (the command line's `--effort`): `none` (ignore the field) or
/// one of [`EFFORT_ROLES`].
pub fn parse_effort(text: &str) -> Result<Option<Role>, LogsError> {
    if text.trim() == "none" {
        return Ok(None);
    }
    let role = Role::parse(text)?;
    check_effort(role)?;
    Ok(Some(role))
}

fn check_effort(role: Role) -> Result<(), LogsError> {
    if EFFORT_ROLES.contains(&role) {
        Ok(())
    } else {
        Err(LogsError::Usage(format!(
            "effort role {role}: must be {} or none",
            EFFORT_ROLES.map(Role::name).join(", ")
        )))
    }
}

/// Largest MCAP record accepted [bytes] (a chunk; recorders write ~1 MiB).
const MAX_RECORD: usize = 256 << 20;
/// Most bytes handed to the MCAP reader per read [bytes]: its buffer grows with the bytes the file
/// really holds, never by a length field's claim (a corrupt chunk header can ask for 4 GiB).
const READ_STEP: usize = 1 << 20;

/// Walks the length prefixes of a Schema or Channel record (other records: nothing to check).
struct Prefixes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Prefixes<'_> {
    fn fixed(&mut self, n: usize) -> Option<()> {
        self.pos = self.pos.checked_add(n).filter(|&e| e <= self.data.len())?;
        Some(())
    }
    /// A u32-length-prefixed field; returns where its bytes start.
    fn sized(&mut self) -> Option<usize> {
        let b: [u8; 4] = self
            .data
            .get(self.pos..self.pos.checked_add(4)?)?
            .try_into()
            .ok()?;
        self.fixed(4)?;
        let start = self.pos;
        self.fixed(u32::from_le_bytes(b) as usize)?;
        Some(start)
    }
}

/// The records of a chunk record's `data`: its header checked, its records decompressed (none,
/// zstd, lz4) as a stream to exactly the size the header gives (at most [`MAX_RECORD`]) and checked
/// against the header's CRC-32 of the uncompressed records (0: not computed, per the MCAP spec). The chunk
/// is handled here, not by the `mcap` crate's reader (which underflows a counter when a record
/// claims more than its chunk holds).
fn chunk_records(data: &[u8]) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    let bad = || "malformed chunk: its header runs past the chunk".to_string();
    let u64_at = |at: usize| -> Result<u64, String> {
        let mut b = [0u8; 8];
        b.copy_from_slice(data.get(at..at + 8).ok_or_else(bad)?);
        Ok(u64::from_le_bytes(b))
    };
    let mut c = Prefixes { data, pos: 0 };
    c.fixed(16).ok_or_else(bad)?; // message start and end time
    let uncompressed = u64_at(c.pos)?;
    c.fixed(8).ok_or_else(bad)?; // uncompressed size
    let mut crc = [0u8; 4];
    crc.copy_from_slice(data.get(c.pos..c.pos + 4).ok_or_else(bad)?);
    let crc = u32::from_le_bytes(crc);
    c.fixed(4).ok_or_else(bad)?; // uncompressed CRC (0: not computed)
    let name = c.sized().ok_or_else(bad)?;
    let compression = &data[name..c.pos];
    let compressed = u64_at(c.pos)?;
    c.fixed(8).ok_or_else(bad)?;
    let body = usize::try_from(compressed)
        .ok()
        .and_then(|n| c.pos.checked_add(n))
        .and_then(|end| data.get(c.pos..end))
        .ok_or_else(|| {
            format!("malformed chunk: compressed size {compressed} exceeds the chunk")
        })?;
    let n = usize::try_from(uncompressed)
        .ok()
        .filter(|&n| n <= MAX_RECORD)
        .ok_or_else(|| {
            format!("chunk of {uncompressed} bytes uncompressed: more than {MAX_RECORD}")
        })?;
    let stream = |r: std::io::Result<Box<dyn Read + '_>>| -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        r.and_then(|r| r.take(n as u64 + 1).read_to_end(&mut out))
            .map_err(|e| format!("chunk ({}): {e}", String::from_utf8_lossy(compression)))?;
        Ok(out)
    };
    let records = match compression {
        b"" => std::borrow::Cow::Borrowed(body),
        b"zstd" => std::borrow::Cow::Owned(stream(
            zstd::stream::read::Decoder::new(body).map(|d| Box::new(d) as Box<dyn Read>),
        )?),
        b"lz4" => std::borrow::Cow::Owned(stream(
            lz4::Decoder::new(body).map(|d| Box::new(d) as Box<dyn Read>),
        )?),
        other => {
            return Err(format!(
                "chunk compression `{}` is not supported (none, zstd, lz4)",
                String::from_utf8_lossy(other)
            ));
        }
    };
    if records.len() != n {
        return Err(format!(
            "malformed chunk: its records are {} bytes, its header says {n}",
            records.len()
        ));
    }
    let computed = crc32fast::hash(&records);
    if crc != 0 && computed != crc {
        return Err(format!(
            "CRC of its records is {computed:08X}, its header says {crc:08X}: the file is damaged"
        ));
    }
    Ok(records)
}

/// Whether every length prefix of a Schema or Channel record fits in the record. The `mcap` crate
/// reserves a string's claimed length before reading it, so a corrupt length in a few bytes of file
/// would allocate up to 4 GiB (an abort, not an error); checked before [`mcap::parse_record`].
fn prefixes_fit(opcode: u8, data: &[u8]) -> bool {
    let mut c = Prefixes { data, pos: 0 };
    let mut walk = || -> Option<()> {
        match opcode {
            op::SCHEMA => {
                c.fixed(2)?; // id
                c.sized()?; // name
                c.sized()?; // encoding
                c.sized()?; // data
            }
            op::CHANNEL => {
                c.fixed(4)?; // id, schema id
                c.sized()?; // topic
                c.sized()?; // message encoding
                let start = c.sized()?; // metadata: key/value strings
                let end = c.pos;
                c.pos = start;
                while c.pos < end {
                    c.sized()?;
                    c.sized()?;
                }
                (c.pos == end).then_some(())?;
            }
            _ => {}
        }
        Some(())
    };
    walk().is_some()
}
const SCHEMA: &str = "sensor_msgs/msg/JointState";

/// Reads one joint from an MCAP bag into a run named after the file stem.
pub fn read(path: &Path, spec: &McapSpec, progress: Progress) -> Result<ImportedRun, LogsError> {
    read_with_base(path, spec, None, progress)
}

/// [`read`], the whole-body state's root-link orientation from the `sensor_msgs/msg/Imu`
/// messages on `base_topic` (their `orientation`, taken as the root link's in the world): each
/// `JointState` row takes the last orientation read before it in the bag's order (sample and
/// hold), its sign continued from the previous one; rows before the first are dropped (counted as
/// non-finite `base_quat_*`). Needs [`McapSpec::state_joints`].
pub fn read_with_base(
    path: &Path,
    spec: &McapSpec,
    base_topic: Option<&str>,
    progress: Progress,
) -> Result<ImportedRun, LogsError> {
    let extra = McapState {
        base_orientation: base_topic.map(str::to_string),
        wrenches: Vec::new(),
    };
    read_state(path, spec, &extra, progress)
}

/// [`read`] with the whole-body state's [`McapState`] topics. Needs [`McapSpec::state_joints`]
/// when any is given.
pub fn read_state(
    path: &Path,
    spec: &McapSpec,
    extra: &McapState,
    progress: Progress,
) -> Result<ImportedRun, LogsError> {
    read_streamed(path, spec, extra, progress, None)
}

/// [`read_state`], handing the rows to `stream` in blocks as they are read instead of holding
/// them (the returned run then has the report and no rows; see [`crate::BlockSink`]).
///
/// Streamed, the first `JointState` message decides which of `position`, `velocity` and `effort`
/// are read (an empty array there: not measured, for the whole bag), and a later message with an
/// empty array where the first had values is an error naming it: the rows already handed on
/// cannot be taken back. (Held whole, a field empty in any message is dropped for the whole bag.)
pub fn read_streamed(
    path: &Path,
    spec: &McapSpec,
    extra: &McapState,
    progress: Progress,
    stream: Option<crate::BlockSink<'_>>,
) -> Result<ImportedRun, LogsError> {
    // Streamed: which of position, velocity, effort the first message lacks. Each block's
    // signals for those are removed before the block goes on (they hold placeholders).
    let absent = Cell::new([false; 3]);
    let streaming = stream.is_some();
    let block_rows = stream.as_ref().map_or(1, |s| s.block_rows);
    let mut inner = stream.map(|s| s.sink);
    let mut masked = |mut block: ImportedRun| -> Result<(), String> {
        let a = absent.get();
        for sig in std::iter::once(&mut block.signals).chain(&mut block.other_joints) {
            drop_absent(sig, a);
        }
        inner.as_mut().map_or(Ok(()), |sink| sink(block))
    };
    let sink = streaming.then_some(crate::BlockSink {
        block_rows,
        sink: &mut masked,
    });
    let state_topics = StateTopics::new(extra);
    if state_topics.any() && spec.state_joints.is_none() {
        return Err(LogsError::Usage(
            "a base orientation or a wrench enters the whole-body state, which only the current \
             label with a URDF reads"
                .into(),
        ));
    }
    if let Some(r) = spec.effort_role {
        // Time, s or ṡ as the effort's role would overwrite a field read from elsewhere.
        check_effort(r)?;
    }
    let (file, total) = open_bag(path)?;
    if spec.all_joints && spec.state_joints.is_none() {
        return Err(LogsError::Usage(
            "all joints: the whole-body state (the URDF's joint names) is needed".into(),
        ));
    }
    if spec.joints.is_empty() && !spec.all_joints {
        return Err(LogsError::Usage("no joint named to read".into()));
    }
    let mut roles = vec![Role::S, Role::Sdot];
    if let Some(r) = spec.effort_role {
        roles.push(r);
    }
    let mut map = RoleMap::si(&roles);
    for &r in &spec.negate {
        map.negate(r)?;
    }
    let mut bag = Bag {
        p: path.display().to_string(),
        spec,
        state_topics,
        absent: streaming.then_some(&absent),
        sink,
        schemas: BTreeMap::new(),
        wanted: Vec::new(),
        topics: BTreeMap::new(),
        names_seen: Vec::new(),
        joints: spec.joints.clone(),
        roles,
        map,
        builder: None,
        state_names: Vec::new(),
        not_in_urdf: Vec::new(),
        state_vel_empty: 0,
        state_qdot: false,
        msg_no: 0,
        t0: None,
        empty: [0; 3],
        first_empty: [None; 3],
    };
    let unclosed = read_records(path, file, total, progress, |opcode, data| {
        bag.record(opcode, data)
    })?;
    bag.finish(path, total, unclosed)
}

/// Opens an MCAP file and checks its magic; the file (read past the magic) and its size.
fn open_bag(path: &Path) -> Result<(std::fs::File, u64), LogsError> {
    let mut file = open_regular(path)?;
    let total = file.metadata().map(|m| m.len()).unwrap_or(0);
    if total == 0 {
        return Err(LogsError::Empty {
            path: path.display().to_string(),
            what: "empty file".into(),
        });
    }
    let mut magic = [0u8; 8];
    let got = file.read(&mut magic).map_err(|e| LogsError::io(path, e))?;
    if got < 8 || magic != *mcap::MAGIC {
        return Err(LogsError::Format {
            path: path.display().to_string(),
            msg: "not an MCAP file (no MCAP magic at the start)".into(),
        });
    }
    Ok((file, total))
}

/// Feeds `file` (of `total` bytes, read past its magic by [`open_bag`]) through the `mcap`
/// crate's linear reader, at most [`READ_STEP`] bytes per read, and hands every record to
/// `handle` (opcode, body), the records of each chunk split here ([`chunk_records`]). Returns
/// where the whole records ended when the file has no footer (a recording killed before it was
/// closed: what is whole is read).
fn read_records(
    path: &Path,
    mut file: std::fs::File,
    total: u64,
    progress: Progress,
    mut handle: impl FnMut(u8, &[u8]) -> Result<(), LogsError>,
) -> Result<Option<u64>, LogsError> {
    let fmt = |msg: String| LogsError::Format {
        path: path.display().to_string(),
        msg,
    };
    // The magic goes through the reader too: the data section's CRC covers it.
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(MAX_RECORD),
    );
    reader
        .insert(mcap::MAGIC.len())
        .copy_from_slice(mcap::MAGIC);
    reader.notify_read(mcap::MAGIC.len());
    let mut done: u64 = 8;
    // Offset of the next record in the file (after the 8-byte magic).
    let mut offset: u64 = 8;
    let mut footer = false;
    while let Some(ev) = reader.next_event() {
        let ev = match ev {
            Ok(ev) => ev,
            Err(mcap::McapError::UnexpectedEof) if !footer => return Ok(Some(offset)),
            Err(mcap::McapError::BadDataCrc { saved, calculated }) => {
                return Err(fmt(format!(
                    "the CRC of the data section (byte 0 to {offset}) is {calculated:08X}, its \
                     data end record says {saved:08X}: the file is damaged"
                )));
            }
            Err(e) => return Err(fmt(format!("at byte {offset}: {e}"))),
        };
        if let LinearReadEvent::Record { data, opcode } = &ev {
            footer |= *opcode == op::FOOTER;
            offset += 9 + data.len() as u64;
        }
        let at = offset;
        match ev {
            LinearReadEvent::ReadRequest(need) => {
                let n = file
                    .read(reader.insert(need.min(READ_STEP)))
                    .map_err(|e| LogsError::io(path, e))?;
                reader.notify_read(n);
                done += n as u64;
                progress(done, total);
            }
            LinearReadEvent::Record { data, opcode } if opcode == op::CHUNK => {
                let start = at - 9 - data.len() as u64;
                let records = chunk_records(data)
                    .map_err(|e| fmt(format!("chunk at byte offset {start}: {e}")))?;
                let mut pos = 0usize;
                while pos < records.len() {
                    let head = records.get(pos..pos + 9).ok_or_else(|| {
                        fmt("malformed chunk: it ends inside a record header".into())
                    })?;
                    let mut len = [0u8; 8];
                    len.copy_from_slice(&head[1..]);
                    let end = usize::try_from(u64::from_le_bytes(len))
                        .ok()
                        .and_then(|l| (pos + 9).checked_add(l))
                        .filter(|&e| e <= records.len())
                        .ok_or_else(|| {
                            fmt("malformed chunk: a record runs past the end of its chunk".into())
                        })?;
                    handle(head[0], &records[pos + 9..end])?;
                    pos = end;
                }
            }
            LinearReadEvent::Record { data, opcode } => handle(opcode, data)?,
        }
    }
    Ok(None)
}

/// One bag being read: the channels met so far, and the `JointState` messages on the topic
/// turned into rows of a [`RunBuilder`] (created at the first one: its names give the
/// whole-body state's joints).
struct Bag<'a, 's> {
    /// The bag's path, for messages.
    p: String,
    spec: &'a McapSpec,
    state_topics: StateTopics<'a>,
    /// Streamed: which of position, velocity, effort the first message lacks (set there).
    absent: Option<&'a Cell<[bool; 3]>>,
    /// Streamed: where the builder hands its blocks (taken when it is created).
    sink: Option<crate::BlockSink<'s>>,
    schemas: BTreeMap<u16, (String, String)>,
    /// Channels of the `JointState` topic.
    wanted: Vec<u16>,
    /// Every topic met, with its schema name.
    topics: BTreeMap<String, String>,
    /// Names of the messages that lack a labelled joint (at most 256, for the error).
    names_seen: Vec<String>,
    /// The labelled joints.
    joints: Vec<String>,
    roles: Vec<Role>,
    map: RoleMap,
    builder: Option<RunBuilder<'s>>,
    state_names: Vec<String>,
    not_in_urdf: Vec<String>,
    state_vel_empty: u64,
    state_qdot: bool,
    msg_no: u64,
    /// The first message's stamp [s since the epoch].
    t0: Option<f64>,
    /// Messages with an empty position, velocity, effort, and the first of each.
    empty: [u64; 3],
    first_empty: [Option<u64>; 3],
}

impl<'s> Bag<'_, 's> {
    fn fmt(&self, msg: String) -> LogsError {
        LogsError::Format {
            path: self.p.clone(),
            msg,
        }
    }

    /// One record (top level or inside a chunk): schemas, channels and messages are parsed, the
    /// rest is skipped.
    fn record(&mut self, opcode: u8, data: &[u8]) -> Result<(), LogsError> {
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Ok(());
        }
        if !prefixes_fit(opcode, data) {
            return Err(self.fmt(format!(
                "a {} record's length field exceeds the record ({} bytes)",
                if opcode == op::SCHEMA {
                    "schema"
                } else {
                    "channel"
                },
                data.len()
            )));
        }
        let rec = mcap::parse_record(opcode, data).map_err(|e| self.fmt(e.to_string()))?;
        match rec {
            Record::Schema { header, .. } => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding));
            }
            Record::Channel(ch) => {
                let schema = self
                    .schemas
                    .get(&ch.schema_id)
                    .map_or("?".to_string(), |s| s.0.clone());
                self.topics.insert(ch.topic.clone(), schema.clone());
                if ch.topic == self.spec.topic {
                    if schema != SCHEMA {
                        return Err(self.fmt(format!(
                            "topic {} carries `{schema}`, not {SCHEMA}",
                            ch.topic
                        )));
                    }
                    if ch.message_encoding != "cdr" {
                        return Err(self.fmt(format!(
                            "topic {} is encoded `{}`, not cdr",
                            ch.topic, ch.message_encoding
                        )));
                    }
                    self.wanted.push(ch.id);
                }
                self.state_topics
                    .channel(&ch.topic, &schema, &ch.message_encoding, ch.id)
                    .map_err(|e| self.fmt(e))?;
            }
            Record::Message { header, data } => {
                let mine = self.state_topics.message(header.channel_id, &data);
                if mine.map_err(|e| self.fmt(e))? || !self.wanted.contains(&header.channel_id) {
                    return Ok(());
                }
                self.msg_no += 1;
                let js = decode_joint_state(&data).map_err(|e| {
                    self.fmt(format!(
                        "message {} on {}: {e}",
                        self.msg_no, self.spec.topic
                    ))
                })?;
                self.check_fields(&js)?;
                if self.builder.is_none() {
                    self.builder = Some(self.start(&js));
                }
                self.row(&js)?;
            }
            _ => {}
        }
        Ok(())
    }

    /// Streamed: the first message decides which fields are read; a later one lacking one of
    /// them is an error.
    fn check_fields(&self, js: &JointState) -> Result<(), LogsError> {
        let Some(absent) = self.absent else {
            return Ok(());
        };
        let lacks = [
            js.position.is_empty(),
            js.velocity.is_empty(),
            self.spec.effort_role.is_some() && js.effort.is_empty(),
        ];
        if self.builder.is_none() {
            if lacks[0] && lacks[1] {
                return Err(self.fmt(format!(
                    "message {} on {}: neither `position` nor `velocity` has values; a streamed \
                     read takes its fields from the first message",
                    self.msg_no, self.spec.topic
                )));
            }
            absent.set(lacks);
        } else if let Some(k) = (0..3).find(|&k| lacks[k] && !absent.get()[k]) {
            return Err(self.fmt(format!(
                "message {} on {}: `{}` is empty, and the first message had values: a streamed \
                 read takes the first message's fields from every message (read the bag whole \
                 to drop the field for the whole bag)",
                self.msg_no,
                self.spec.topic,
                ["position", "velocity", "effort"][k]
            )));
        }
        Ok(())
    }

    /// The builder, at the first message: its names give the whole-body state's joints (and,
    /// with `all_joints`, the labelled ones).
    fn start(&mut self, js: &JointState) -> RunBuilder<'s> {
        let layout = self.spec.state_joints.as_ref().map(|urdf| {
            // Every name is kept (the pipeline lists the URDF's missing ones).
            for n in &js.name {
                if !urdf.contains(n) && !self.not_in_urdf.contains(n) {
                    self.not_in_urdf.push(n.clone());
                }
                if !self.state_names.contains(n) {
                    self.state_names.push(n.clone());
                }
            }
            let mut l = crate::StateLayout::positions(self.state_names.clone());
            if !js.velocity.is_empty() {
                l.qdot = vec![true; self.state_names.len()];
                self.state_qdot = true;
            }
            self.state_topics.layout(&mut l);
            l
        });
        if self.spec.all_joints {
            self.joints = self
                .state_names
                .iter()
                .filter(|n| !self.not_in_urdf.contains(n))
                .cloned()
                .collect();
        }
        let mut b = RunBuilder::with_joints(
            self.map.clone(),
            self.joints.clone(),
            layout,
            &self.p,
            "mcap",
        )
        .streaming(self.sink.take());
        let rep = b.report_mut();
        rep.sources
            .insert("time".into(), "header.stamp - first stamp".into());
        rep.sources.insert("s".into(), "position".into());
        rep.sources.insert("sdot".into(), "velocity".into());
        if let Some(r) = self.spec.effort_role {
            rep.sources.insert(r.name().into(), "effort".into());
        }
        b
    }

    /// One message's row: time, each labelled joint's roles, the whole-body state.
    fn row(&mut self, js: &JointState) -> Result<(), LogsError> {
        let msg_no = self.msg_no;
        let topic = &self.spec.topic;
        let mut idx = Vec::with_capacity(self.joints.len());
        for joint in &self.joints {
            if js.name.iter().filter(|n| *n == joint).count() > 1 {
                return Err(self.fmt(format!(
                    "message {msg_no} on {topic}: joint `{joint}` is named more than once in \
                     `name` ({}): which entry holds it is ambiguous",
                    js.name.join(", ")
                )));
            }
            match js.name.iter().position(|n| n == joint) {
                Some(j) => idx.push(j),
                None => {
                    for n in &js.name {
                        if !self.names_seen.contains(n) && self.names_seen.len() < 256 {
                            self.names_seen.push(n.clone());
                        }
                    }
                    let b = self.builder.as_mut().expect("created before the first row");
                    if self.joints.len() == 1 {
                        b.skip("joint not in message");
                    } else {
                        b.skip(&format!("joint {joint} not in message"));
                    }
                    return Ok(());
                }
            }
        }
        // An empty array is "not measured": a placeholder 0 now, and the whole signal is
        // dropped at the end if any message lacked it. A wrong length is a broken message:
        // NaN, counted and dropped.
        let first_empty = &mut self.first_empty;
        let mut pick = |v: &[f64], j: usize, k: usize, empty: &mut [u64; 3]| {
            if v.is_empty() {
                empty[k] += 1;
                first_empty[k].get_or_insert(msg_no);
                0.0
            } else if v.len() == js.name.len() {
                v[j]
            } else {
                f64::NAN
            }
        };
        let t = js.stamp_s - *self.t0.get_or_insert(js.stamp_s);
        let mut vals = Vec::with_capacity(1 + self.roles.len() * idx.len());
        vals.push(t);
        for (n, &j) in idx.iter().enumerate() {
            // Count an empty array once per message, not once per joint.
            let mut e = [0u64; 3];
            let pos = pick(&js.position, j, 0, &mut e);
            let vel = pick(&js.velocity, j, 1, &mut e);
            let eff = pick(&js.effort, j, 2, &mut e);
            if n == 0 {
                for (k, x) in e.iter().enumerate() {
                    self.empty[k] += x;
                }
            }
            vals.extend([pos, vel]);
            if self.spec.effort_role.is_some() {
                vals.push(eff);
            }
        }
        if self.state_qdot && js.velocity.is_empty() {
            self.state_vel_empty += 1;
        }
        for name in &self.state_names {
            let k = js.name.iter().position(|n| n == name);
            let at = |v: &[f64]| match k {
                Some(k) if v.len() == js.name.len() => v[k],
                _ => f64::NAN,
            };
            vals.push(at(&js.position));
            if self.state_qdot {
                vals.push(if js.velocity.is_empty() {
                    0.0
                } else {
                    at(&js.velocity)
                });
            }
        }
        self.state_topics
            .extend_row(&mut vals, topic, msg_no, &self.topics)
            .map_err(|e| self.fmt(e))?;
        let b = self.builder.as_mut().expect("created before the first row");
        if let Some(f) = self.state_topics.base_frame() {
            b.set_base_frame(f);
        }
        let row = b.row_mut();
        row[..vals.len()].copy_from_slice(&vals);
        b.push(|| format!("message {msg_no}"), 0)
    }

    /// The run, once every record is read: the checks that need the whole bag, the report's
    /// notes and warnings, the signals of a field empty in some message dropped.
    fn finish(
        mut self,
        path: &Path,
        total: u64,
        unclosed: Option<u64>,
    ) -> Result<ImportedRun, LogsError> {
        self.check_complete()?;
        let Some(mut b) = self.builder.take() else {
            return Err(LogsError::Empty {
                path: self.p,
                what: format!("no message on {}", self.spec.topic),
            });
        };
        self.say(b.report_mut(), total, unclosed);
        let name = path
            .file_stem()
            .map_or_else(|| "run".to_string(), |s| s.to_string_lossy().into_owned());
        let mut run = b.finish(&self.p, name)?;
        let empty = self.empty;
        for sig in std::iter::once(&mut run.signals).chain(&mut run.other_joints) {
            drop_absent(sig, [empty[0] > 0, empty[1] > 0, empty[2] > 0]);
            if sig.s_rad.is_none() && sig.sdot_rad_s.is_none() {
                return Err(LogsError::Format {
                    path: self.p.clone(),
                    msg: format!(
                        "joint {}: neither position nor velocity is in every message",
                        self.joints.join(", ")
                    ),
                });
            }
        }
        if self.state_vel_empty > 0
            && let Some(st) = &mut run.state
        {
            st.qdot.iter_mut().for_each(|v| *v = None);
        }
        Ok(run)
    }

    /// The checks that need the whole bag: the topic exists, so do the state's topics, and some
    /// message named the labelled joints.
    fn check_complete(&self) -> Result<(), LogsError> {
        let spec = self.spec;
        if self.wanted.is_empty() {
            let list: Vec<String> = self
                .topics
                .iter()
                .map(|(t, s)| format!("{t} ({s})"))
                .collect();
            return Err(self.fmt(format!(
                "no topic {}; the bag has: {}",
                spec.topic,
                if list.is_empty() {
                    "no channels".into()
                } else {
                    list.join(", ")
                }
            )));
        }
        self.state_topics
            .check_present(&self.topics)
            .map_err(|e| self.fmt(e))?;
        if self.msg_no > 0 && self.t0.is_none() {
            return Err(LogsError::JointNotFound {
                path: self.p.clone(),
                joint: self.joints.join(", "),
                available: self.names_seen.join(", "),
            });
        }
        Ok(())
    }

    /// The report's notes (the whole-body state, the time origin) and warnings (an unclosed
    /// recording of `total` bytes, fields empty in some messages).
    fn say(&self, rep: &mut crate::RunReport, total: u64, unclosed: Option<u64>) {
        let (spec, msg_no, empty) = (self.spec, self.msg_no, self.empty);
        if spec.state_joints.is_some() {
            rep.notes.push(format!(
                "whole-body state: {} joints of the first message's names{}",
                self.state_names.len(),
                if self.state_vel_empty > 0 {
                    format!(
                        "; velocity empty in {} messages: the state's velocities are not used",
                        self.state_vel_empty
                    )
                } else {
                    String::new()
                }
            ));
            if !self.not_in_urdf.is_empty() {
                rep.notes.push(format!(
                    "names in the messages that the URDF lacks (not used): {}",
                    self.not_in_urdf.join(", ")
                ));
            }
            self.state_topics.report(rep);
        }
        if let Some(t0) = self.t0 {
            rep.notes.push(format!(
                "time origin: first header.stamp = {t0:.9} s since the epoch"
            ));
        }
        if let Some(at) = unclosed {
            rep.warnings.push(format!(
                "no footer: the recording was not closed (killed?); the {msg_no} messages on {} in \
                 the whole records before byte {at} were read, the last {} bytes (an unfinished \
                 record) were not",
                spec.topic,
                total.saturating_sub(at)
            ));
        }
        for (k, f) in ["position", "velocity", "effort"].iter().enumerate() {
            if empty[k] == 0 || (k == 2 && spec.effort_role.is_none()) {
                continue;
            }
            let what = if k == 2 {
                spec.effort_role
                    .map_or("-".into(), |r| r.name().to_string())
            } else {
                ["s", "sdot"][k].to_string()
            };
            rep.warnings.push(format!(
                "field `{f}` is empty (not measured) in {} of {msg_no} messages (first: message \
                 {}): {what} is not used for the whole bag",
                empty[k],
                self.first_empty[k].unwrap_or(0)
            ));
        }
    }
}

/// Removes from `sig` the signals of the `JointState` fields marked absent: position, velocity,
/// effort (whichever role it was read as).
fn drop_absent(sig: &mut crate::RunSignals, absent: [bool; 3]) {
    if absent[0] {
        sig.s_rad = None;
    }
    if absent[1] {
        sig.sdot_rad_s = None;
    }
    if absent[2] {
        sig.tau_joint_nm = None;
        sig.tau_motor_nm = None;
        sig.tau_f_nm = None;
        sig.current_a = None;
    }
}
