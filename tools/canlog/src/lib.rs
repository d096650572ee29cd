//! # `frictionless-canlog`: candump log files (`candump -L` format): parse, write, record, replay
//!
//! Crate table: `tools/canlog`; depends on `frictionless-drives` (wire frames), socketcan and
//! `frictionless` (its [`frictionless::regular_file`] reads); used by
//! `frictl` (`frictl can record/replay`) and the fuzz crate (`candump_parse`).
//!
//! What this crate **is**:
//! - [`parse_line`] / [`parse_log`] / [`write_entry`]: the log line `(sec.usec) iface ID#DATA` with
//!   exactly 6 fractional digits; 3 hex digits = standard id, 8 = extended; `ID#R` / `ID#R<dlc>` remote
//!   frames; `ID##<flags nibble><data>` CAN FD; `ID#<8 bytes>_<dlc hex>` a classic frame whose raw DLC
//!   is 9..=15 (`socketcan-rs/socketcan-rs`: `doc/CanDumpLogFormat.md`). Errors carry the line number
//!   and the offending text ([`CanLogError`]).
//! - [`replay`]: paces entries by their timestamps with absolute deadlines (no drift, no bursts ahead
//!   of time; the kernel silently drops frames when a reader falls behind).
//! - [`record`] / [`replay_to_iface`]: the socket side, on SocketCAN via the `socketcan` crate.
//!
//! What it is **not**: no error-frame lines (ids with the CAN_ERR flag are refused), no filtering, no
//! ASCII-art candump output.
//!
//! ## Example: parse a `candump -L` log, re-write it, decode a frame
//! ```
//! use frictionless_canlog::{LogFrame, format_entry, parse_line, parse_log, write_entry};
//! use frictionless_drives::can::mit::{self, MitRanges, MitRx, MitSpecial};
//!
//! // Motor 3 told to enter MIT motor mode, then an ODrive-style extended-id remote frame.
//! let line = "(1700000000.000123) can0 003#FFFFFFFFFFFFFFFC";
//! let e = parse_line(line, 1, "bus.log")?;
//! assert_eq!((e.stamp_us, e.iface.as_str()), (1_700_000_000_000_123, "can0"));
//! let LogFrame::Can { frame, len8_dlc: None } = &e.frame else { panic!("a classic frame") };
//! assert_eq!((frame.id, frame.extended, frame.len), (3, false, 8));
//! // The frames are the codecs' `WireFrame`s: decode with `frictionless-drives`.
//! let rx = mit::decode_command(frame, &MitRanges::MINI_CHEETAH).expect("an MIT frame");
//! assert_eq!(rx, MitRx::Special(MitSpecial::EnterMotorMode));
//!
//! // Writing gives the same text back, so a log survives read → write unchanged.
//! assert_eq!(format_entry(&e), line);
//! let log = format!("{line}\n(1700000000.001123) can0 00000069#R8\n");
//! let entries = parse_log(log.as_bytes(), "bus.log")?;
//! let mut out = Vec::new();
//! for e in &entries {
//!     write_entry(&mut out, e)?;
//! }
//! assert_eq!(String::from_utf8(out)?, log);
//!
//! // Errors name the file, the line and the text.
//! let err = parse_line("(1.5) can0 003#00", 7, "bus.log").unwrap_err();
//! assert!(err.to_string().starts_with("bus.log: line 7:"), "{err}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};
use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::frame::{EFF_MAX, SFF_MAX};

/// Valid CAN FD payload lengths.
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// A CAN FD frame as logged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FdFrame {
    /// Arbitration id.
    pub id: u32,
    /// 29-bit id.
    pub extended: bool,
    /// Flags nibble (bit 0 BRS, bit 1 ESI).
    pub flags: u8,
    /// Payload, a length in [`FD_LENGTHS`].
    pub data: Vec<u8>,
}

/// The frame of one log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LogFrame {
    /// Classic CAN (data or remote).
    Can {
        /// The frame.
        frame: WireFrame,
        /// Raw DLC 9..=15 of an 8-byte classic frame (`_` escape), if any.
        len8_dlc: Option<u8>,
    },
    /// CAN FD.
    Fd(FdFrame),
}

/// One log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogEntry {
    /// Timestamp [µs since the epoch of the log, usually Unix time].
    pub stamp_us: u64,
    /// Interface name.
    pub iface: String,
    /// The frame.
    pub frame: LogFrame,
}

/// Error reading, parsing or writing a candump log.
#[derive(Debug, thiserror::Error)]
pub enum CanLogError {
    /// A line does not follow the format.
    #[error("{path}: line {line}: {what}: `{text}`")]
    Parse {
        /// File (or `<input>`).
        path: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
        /// The line.
        text: String,
    },
    /// I/O on a file or socket.
    #[error("{what} {path}: {source}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// File or interface.
        path: String,
        /// The error.
        source: io::Error,
    },
    /// A frame cannot be put on the bus (bad id/length).
    #[error("line {index}: frame not sendable: {msg}")]
    Frame {
        /// 1-based entry index.
        index: usize,
        /// Why.
        msg: String,
    },
}

fn hex_val(c: u8) -> Option<u8> {
    (c as char).to_digit(16).map(|d| d as u8)
}

fn parse_hex_bytes(s: &str) -> Result<Vec<u8>, String> {
    let digits: Vec<u8> = s.bytes().filter(|&c| c != b'.').collect();
    if !digits.len().is_multiple_of(2) {
        return Err(format!("odd number of hex digits in data `{s}`"));
    }
    digits
        .chunks(2)
        .map(|p| match (hex_val(p[0]), hex_val(p[1])) {
            (Some(h), Some(l)) => Ok(h << 4 | l),
            _ => Err(format!("bad hex byte `{}`", String::from_utf8_lossy(p))),
        })
        .collect()
}

/// The timestamp `(sec.usec)` in µs (exactly 6 fraction digits).
fn parse_stamp_us(ts: &str) -> Result<u64, String> {
    let ts = ts
        .strip_prefix('(')
        .and_then(|t| t.strip_suffix(')'))
        .ok_or("timestamp not in parentheses")?;
    let (sec, usec) = ts.split_once('.').ok_or("timestamp without `.`")?;
    if sec.is_empty() || !sec.bytes().all(|c| c.is_ascii_digit()) {
        return Err(format!("bad seconds `{sec}`"));
    }
    if usec.len() != 6 || !usec.bytes().all(|c| c.is_ascii_digit()) {
        return Err(format!("fraction `{usec}` must be exactly 6 digits"));
    }
    let sec: u64 = sec
        .parse()
        .map_err(|_| format!("seconds `{sec}` too large"))?;
    let usec: u64 = usec.parse().map_err(|_| "bad fraction".to_string())?;
    sec.checked_mul(1_000_000)
        .and_then(|s| s.checked_add(usec))
        .ok_or_else(|| "timestamp overflows u64 µs".to_string())
}

/// The frame id's value and whether it is extended (3 hex digits: standard, 8: extended).
fn parse_id(id_s: &str) -> Result<(u32, bool), String> {
    let extended = match id_s.len() {
        3 => false,
        8 => true,
        n => {
            return Err(format!(
                "id `{id_s}` has {n} hex digits (3 = standard, 8 = extended)"
            ));
        }
    };
    let id = u32::from_str_radix(id_s, 16).map_err(|_| format!("bad hex id `{id_s}`"))?;
    let max = if extended { EFF_MAX } else { SFF_MAX };
    if id > max {
        return Err(format!(
            "id {id_s} out of range (error frames are not supported)"
        ));
    }
    Ok((id, extended))
}

/// A classic data frame's `data[_dlc]` after the `#` (a raw DLC 9..F only with 8 bytes).
fn parse_classic(id: u32, extended: bool, rest: &str) -> Result<LogFrame, String> {
    let (data_s, dlc_s) = match rest.split_once('_') {
        Some((d, l)) => (d, Some(l)),
        None => (rest, None),
    };
    let data = parse_hex_bytes(data_s)?;
    if data.len() > 8 {
        return Err(format!("{} data bytes > 8 in a classic frame", data.len()));
    }
    let len8_dlc = match dlc_s {
        None => None,
        Some(l) => {
            let v = (l.len() == 1)
                .then(|| hex_val(l.as_bytes()[0]))
                .flatten()
                .filter(|v| (9..=15).contains(v))
                .ok_or(format!("bad raw DLC `_{l}` (9..F)"))?;
            if data.len() != 8 {
                return Err("raw DLC `_` needs exactly 8 data bytes".into());
            }
            Some(v)
        }
    };
    Ok(LogFrame::Can {
        frame: WireFrame::data_frame(id, extended, &data).map_err(|e| e.to_string())?,
        len8_dlc,
    })
}

/// Parses one line's fields; errors are plain messages (the caller adds line number and text).
fn parse_fields(line: &str) -> Result<LogEntry, String> {
    let mut it = line.split_ascii_whitespace();
    let (Some(ts), Some(iface), Some(frame), None) = (it.next(), it.next(), it.next(), it.next())
    else {
        return Err("expected `(sec.usec) iface frame`".into());
    };
    let stamp_us = parse_stamp_us(ts)?;

    let (id_s, rest) = frame.split_once('#').ok_or("frame without `#`")?;
    let (id, extended) = parse_id(id_s)?;
    let frame = if let Some(fd) = rest.strip_prefix('#') {
        let mut b = fd.bytes();
        let flags = b
            .next()
            .and_then(hex_val)
            .ok_or("FD frame needs a flags nibble after `##`")?;
        let data = parse_hex_bytes(&fd[1..])?;
        if !FD_LENGTHS.contains(&data.len()) {
            return Err(format!("{} bytes is not a valid CAN FD length", data.len()));
        }
        LogFrame::Fd(FdFrame {
            id,
            extended,
            flags,
            data,
        })
    } else if let Some(r) = rest.strip_prefix('R') {
        let dlc = match r {
            "" => 0,
            d if d.len() == 1 => hex_val(d.as_bytes()[0])
                .filter(|&v| v <= 8)
                .ok_or(format!("bad remote DLC `{d}`"))?,
            d => return Err(format!("bad remote DLC `{d}`")),
        };
        LogFrame::Can {
            frame: WireFrame::remote(id, extended, dlc).map_err(|e| e.to_string())?,
            len8_dlc: None,
        }
    } else {
        parse_classic(id, extended, rest)?
    };
    if iface.is_empty() || iface.len() > 15 {
        return Err(format!("bad interface name `{iface}`"));
    }
    Ok(LogEntry {
        stamp_us,
        iface: iface.to_string(),
        frame,
    })
}

/// Parses one line (`lineno` is 1-based, for the error).
pub fn parse_line(line: &str, lineno: usize, path: &str) -> Result<LogEntry, CanLogError> {
    parse_fields(line.trim_end_matches(['\r', '\n'])).map_err(|what| CanLogError::Parse {
        path: path.to_string(),
        line: lineno,
        what,
        text: line.trim_end().to_string(),
    })
}

/// Parses a whole log; blank lines are skipped.
pub fn parse_log(reader: impl BufRead, path: &str) -> Result<Vec<LogEntry>, CanLogError> {
    let mut out = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|source| CanLogError::Io {
            what: "reading",
            path: path.to_string(),
            source,
        })?;
        if line.trim().is_empty() {
            continue;
        }
        out.push(parse_line(&line, i + 1, path)?);
    }
    Ok(out)
}

/// Reads and parses a log file.
pub fn read_log(path: &Path) -> Result<Vec<LogEntry>, CanLogError> {
    let (f, _) = frictionless::regular_file::open(path).map_err(|source| CanLogError::Io {
        what: "opening",
        path: path.display().to_string(),
        source,
    })?;
    parse_log(io::BufReader::new(f), &path.display().to_string())
}

/// Formats one entry as a log line (without newline).
pub fn format_entry(e: &LogEntry) -> String {
    let mut s = String::with_capacity(64);
    let _ = write!(
        s,
        "({}.{:06}) {} ",
        e.stamp_us / 1_000_000,
        e.stamp_us % 1_000_000,
        e.iface
    );
    let id = |s: &mut String, id: u32, ext: bool| {
        let _ = if ext {
            write!(s, "{id:08X}")
        } else {
            write!(s, "{id:03X}")
        };
    };
    match &e.frame {
        LogFrame::Can { frame, len8_dlc } => {
            id(&mut s, frame.id, frame.extended);
            s.push('#');
            if frame.rtr {
                s.push('R');
                if frame.len > 0 {
                    let _ = write!(s, "{:X}", frame.len);
                }
            } else {
                for b in frame.payload() {
                    let _ = write!(s, "{b:02X}");
                }
                if let Some(d) = len8_dlc {
                    let _ = write!(s, "_{d:X}");
                }
            }
        }
        LogFrame::Fd(fd) => {
            id(&mut s, fd.id, fd.extended);
            let _ = write!(s, "##{:X}", fd.flags & 0xF);
            for b in &fd.data {
                let _ = write!(s, "{b:02X}");
            }
        }
    }
    s
}

/// Writes one entry as a line.
pub fn write_entry(w: &mut impl Write, e: &LogEntry) -> io::Result<()> {
    writeln!(w, "{}", format_entry(e))
}

/// Paces `entries` by their timestamps: entry k is handed to `send` at `start + (t_k − t_0)/speed`
/// (absolute deadlines, so sleep overshoot does not accumulate). `loops` = 0 repeats forever (until
/// `send` fails); each loop restarts the schedule one inter-frame gap (or 1 ms) after the last frame.
/// `send` gets the entry's index and the entry. Returns the number of frames sent.
pub fn replay<E>(
    entries: &[LogEntry],
    speed: f64,
    loops: u64,
    send: impl FnMut(usize, &LogEntry) -> Result<(), E>,
) -> Result<u64, E> {
    let start = Instant::now();
    replay_scheduled(
        entries,
        speed,
        loops,
        |offset| {
            let deadline = start + offset;
            let now = Instant::now();
            if deadline > now {
                std::thread::sleep(deadline - now);
            }
        },
        send,
    )
}

/// The schedule behind [`replay`] with the clock left to the caller: before each frame,
/// `wait_until(offset)` is called with the frame's deadline as an offset from the replay's start,
/// then `send` runs. [`replay`] passes a sleeping clock; tests pass a recording one.
pub fn replay_scheduled<E>(
    entries: &[LogEntry],
    speed: f64,
    loops: u64,
    mut wait_until: impl FnMut(Duration),
    mut send: impl FnMut(usize, &LogEntry) -> Result<(), E>,
) -> Result<u64, E> {
    let speed = if speed.is_finite() && speed > 0.0 {
        speed
    } else {
        1.0
    };
    let Some(first) = entries.first() else {
        return Ok(0);
    };
    let t0 = first.stamp_us;
    let span_us = entries.last().map_or(0, |l| l.stamp_us.saturating_sub(t0));
    let gap_us = if entries.len() > 1 {
        span_us as f64 / (entries.len() - 1) as f64
    } else {
        1000.0
    };
    let loop_us = (span_us as f64 + gap_us.max(1.0)) / speed;
    let mut sent = 0;
    let mut k = 0u64;
    while loops == 0 || k < loops {
        for (i, e) in entries.iter().enumerate() {
            let offset_us = k as f64 * loop_us + e.stamp_us.saturating_sub(t0) as f64 / speed;
            wait_until(Duration::from_secs_f64(offset_us * 1e-6));
            send(i, e)?;
            sent += 1;
        }
        k += 1;
    }
    Ok(sent)
}

/// Converts a log frame to a socketcan frame.
pub fn to_socketcan(f: &LogFrame) -> Result<socketcan::CanAnyFrame, String> {
    use socketcan::{CanAnyFrame, CanFdFrame, CanFrame, ExtendedId, Id, StandardId, id::FdFlags};
    match f {
        LogFrame::Can { frame, .. } => CanFrame::try_from(*frame)
            .map(CanAnyFrame::from)
            .map_err(|e| e.to_string()),
        LogFrame::Fd(fd) => {
            let id: Id = if fd.extended {
                ExtendedId::new(fd.id).ok_or("bad id")?.into()
            } else {
                StandardId::new(fd.id as u16).ok_or("bad id")?.into()
            };
            CanFdFrame::with_flags(id, &fd.data, FdFlags::from_bits_truncate(fd.flags))
                .map(CanAnyFrame::Fd)
                .ok_or_else(|| format!("bad FD frame length {}", fd.data.len()))
        }
    }
}

/// Converts a received socketcan frame to a log frame (`None` for error frames).
pub fn from_socketcan(f: &socketcan::CanAnyFrame) -> Option<LogFrame> {
    use socketcan::{CanAnyFrame, EmbeddedFrame, Frame};
    match f {
        CanAnyFrame::Normal(d) => Some(LogFrame::Can {
            frame: WireFrame::data_frame(d.raw_id(), d.is_extended(), d.data()).ok()?,
            len8_dlc: None,
        }),
        CanAnyFrame::Remote(r) => Some(LogFrame::Can {
            frame: WireFrame::remote(r.raw_id(), r.is_extended(), r.dlc().min(8) as u8).ok()?,
            len8_dlc: None,
        }),
        CanAnyFrame::Fd(fd) => Some(LogFrame::Fd(FdFrame {
            id: fd.raw_id(),
            extended: fd.is_extended(),
            flags: fd.flags().bits() & 0x3,
            data: fd.data().to_vec(),
        })),
        CanAnyFrame::Error(_) => None,
    }
}

/// Microseconds since the Unix epoch (the candump timestamp).
pub fn unix_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// Replays a log on interface `iface` (or each entry's own interface when `None`). Opens a CAN FD
/// socket only when the log holds FD frames. Returns the number of frames sent.
pub fn replay_to_iface(
    entries: &[LogEntry],
    iface: Option<&str>,
    speed: f64,
    loops: u64,
) -> Result<u64, CanLogError> {
    use socketcan::{CanFdSocket, CanSocket, Socket};
    enum Sock {
        Classic(CanSocket),
        Fd(CanFdSocket),
    }
    let has_fd = entries.iter().any(|e| matches!(e.frame, LogFrame::Fd(_)));
    let mut socks: Vec<(String, Sock)> = Vec::new();
    let mut frames = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter().enumerate() {
        frames
            .push(to_socketcan(&e.frame).map_err(|msg| CanLogError::Frame { index: i + 1, msg })?);
        let name = iface.unwrap_or(&e.iface).to_string();
        if !socks.iter().any(|(n, _)| *n == name) {
            let io = |source| CanLogError::Io {
                what: "opening CAN interface",
                path: name.clone(),
                source,
            };
            let s = if has_fd {
                Sock::Fd(CanFdSocket::open(&name).map_err(io)?)
            } else {
                Sock::Classic(CanSocket::open(&name).map_err(io)?)
            };
            socks.push((name, s));
        }
    }
    replay(entries, speed, loops, |k, e| {
        let name = iface.unwrap_or(&e.iface);
        let (_, s) = socks
            .iter()
            .find(|(n, _)| n == name)
            .expect("socket opened above for every interface");
        let r = match (s, &frames[k]) {
            (Sock::Fd(s), f) => s.write_frame_insist(f),
            (Sock::Classic(s), socketcan::CanAnyFrame::Normal(d)) => s.write_frame_insist(d),
            (Sock::Classic(s), socketcan::CanAnyFrame::Remote(r)) => s.write_frame_insist(r),
            (Sock::Classic(_), _) => unreachable!("FD frames open an FD socket"),
        };
        r.map_err(|source| CanLogError::Io {
            what: "writing to",
            path: name.to_string(),
            source,
        })
    })
}

/// Records frames from `iface` to `out` until `stop()` returns true, `max_frames` frames were
/// written (0 = no limit) or `duration` elapsed. Timestamps are taken at reception (Unix µs).
/// Returns the number of frames written.
pub fn record(
    iface: &str,
    out: &mut impl Write,
    max_frames: u64,
    duration: Option<Duration>,
    stop: &dyn Fn() -> bool,
) -> Result<u64, CanLogError> {
    use socketcan::{CanFdSocket, Socket};
    let io = |what: &'static str| {
        move |source| CanLogError::Io {
            what,
            path: iface.to_string(),
            source,
        }
    };
    let sock = CanFdSocket::open(iface).map_err(io("opening CAN interface"))?;
    let started = Instant::now();
    let mut n = 0;
    let mut last_flush = Instant::now();
    while !stop() && (max_frames == 0 || n < max_frames) {
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
        match sock.read_frame_timeout(Duration::from_millis(50)) {
            Ok(f) => {
                if let Some(frame) = from_socketcan(&f) {
                    let e = LogEntry {
                        stamp_us: unix_us(),
                        iface: iface.to_string(),
                        frame,
                    };
                    write_entry(out, &e).map_err(io("writing log for"))?;
                    n += 1;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                ) => {}
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(io("reading from")(e)),
        }
        if last_flush.elapsed() > Duration::from_millis(100) {
            out.flush().map_err(io("writing log for"))?;
            last_flush = Instant::now();
        }
    }
    out.flush().map_err(io("writing log for"))?;
    Ok(n)
}
