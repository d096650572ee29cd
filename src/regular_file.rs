//! Opening and reading the files a user names: regular files only, never blocking, bounded.
//!
//! Every path that comes from a command line, a config or a sidecar goes through here: a FIFO would
//! block a plain `open` or `read` forever, `/dev/zero` would grow memory until the process dies, a
//! directory gives an unhelpful OS error late. [`open`] opens with `O_NONBLOCK` (a FIFO cannot block the
//! open; the flag has no effect on a regular file's reads) after checking the path's type, and checks
//! the *open* file's type again with `fstat` (a path swapped for a FIFO in between cannot slip through);
//! [`read`] and [`read_to_string`] also refuse a file over a size limit before reading and read at
//! most that many bytes.
//!
//! Errors are [`std::io::Error`]s, so they drop into every crate's existing "cannot read PATH: …"
//! error; a refusal carries a [`Refused`] (reach it with [`Refused::of`]) for callers that report it
//! in their own words. Like `std::fs`, the messages do not repeat the path: the caller names it.
//!
//! ```
//! use frictionless::regular_file;
//! let dir = std::env::temp_dir();
//! let err = regular_file::read_text(&dir).unwrap_err();
//! assert_eq!(
//!     regular_file::Refused::of(&err),
//!     Some(&regular_file::Refused::NotRegular { file_type: "directory" })
//! );
//! assert_eq!(err.to_string(), "not a regular file (directory)");
//! ```

use std::fs::{File, FileType};
use std::io::{self, Read};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

/// Size limit for the text files the tools read whole (URDF, TOML configs, JSON sidecars and
/// reports): 64 MiB, far above any real one (a 101-joint TIAGo dual URDF is 0.3 MB).
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// Why a path was refused before any byte of it was read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Refused {
    /// Not a regular file: a FIFO, a device, a socket or a directory.
    NotRegular {
        /// What it is instead, e.g. "FIFO", "character device", "directory".
        file_type: &'static str,
    },
    /// Larger than the limit for this kind of file.
    TooLarge {
        /// Bytes in the file.
        len: u64,
        /// The limit.
        max: u64,
    },
}

impl Refused {
    /// The refusal inside an error from this module (`None` for an OS error such as "not found").
    pub fn of(e: &io::Error) -> Option<&Refused> {
        e.get_ref()
            .and_then(|inner| inner.downcast_ref::<Refused>())
    }

    fn into_io(self) -> io::Error {
        let kind = match self {
            Refused::NotRegular { .. } => io::ErrorKind::InvalidInput,
            Refused::TooLarge { .. } => io::ErrorKind::FileTooLarge,
        };
        io::Error::new(kind, self)
    }
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refused::NotRegular { file_type } => write!(f, "not a regular file ({file_type})"),
            Refused::TooLarge { len, max } => {
                write!(
                    f,
                    "{len} bytes, more than the {max}-byte limit for this file"
                )
            }
        }
    }
}

impl std::error::Error for Refused {}

/// What a non-regular file is, in words.
pub fn file_type_name(t: FileType) -> &'static str {
    if t.is_dir() {
        "directory"
    } else if t.is_fifo() {
        "FIFO"
    } else if t.is_char_device() {
        "character device"
    } else if t.is_block_device() {
        "block device"
    } else if t.is_socket() {
        "socket"
    } else if t.is_file() {
        "regular file"
    } else {
        "not a regular file"
    }
}

/// Opens `path` for reading if it is a regular file; returns the file and its size in bytes.
///
/// The path's type is checked before the open too: opening some devices has effects of its own (a
/// watchdog device starts counting, a tape rewinds).
pub fn open(path: &Path) -> io::Result<(File, u64)> {
    let refuse = |t: FileType| {
        Refused::NotRegular {
            file_type: file_type_name(t),
        }
        .into_io()
    };
    let before = std::fs::metadata(path)?;
    if !before.file_type().is_file() {
        return Err(refuse(before.file_type()));
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let meta = file.metadata()?;
    if !meta.file_type().is_file() {
        return Err(refuse(meta.file_type()));
    }
    Ok((file, meta.len()))
}

/// The bytes of the regular file `path`, refused if it holds more than `max` bytes.
pub fn read(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    let (file, len) = open(path)?;
    if len > max {
        return Err(Refused::TooLarge { len, max }.into_io());
    }
    // One byte more than the size: a file that grew since `fstat` is refused, not truncated.
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0).saturating_add(1));
    file.take(len.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(Refused::TooLarge {
            len: bytes.len() as u64,
            max,
        }
        .into_io());
    }
    Ok(bytes)
}

/// The UTF-8 text of a regular file of at most [`MAX_TEXT_BYTES`]: a URDF, a TOML config, a JSON
/// sidecar or report.
pub fn read_text(path: &Path) -> io::Result<String> {
    read_to_string(path, MAX_TEXT_BYTES)
}

/// The UTF-8 text of the regular file `path`, refused if it holds more than `max` bytes.
pub fn read_to_string(path: &Path, max: u64) -> io::Result<String> {
    String::from_utf8(read(path, max)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("frictionless-rf-{}-{name}", std::process::id()));
        let _ = std::fs::remove_file(&d);
        d
    }

    #[test]
    fn a_fifo_is_refused_without_blocking() {
        let p = tmp("fifo");
        let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = read_to_string(&p, MAX_TEXT_BYTES).unwrap_err();
        assert_eq!(
            Refused::of(&e),
            Some(&Refused::NotRegular { file_type: "FIFO" })
        );
        assert!(open(&p).is_err());
        std::fs::remove_file(&p).unwrap();
    }

    #[test]
    fn a_device_is_refused() {
        let e = read(Path::new("/dev/zero"), MAX_TEXT_BYTES).unwrap_err();
        assert_eq!(e.to_string(), "not a regular file (character device)");
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
    }

    #[test]
    fn size_limit_and_utf8_are_checked() {
        let p = tmp("big");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read(&p, 10).unwrap(), b"0123456789");
        let e = read(&p, 9).unwrap_err();
        assert_eq!(
            Refused::of(&e),
            Some(&Refused::TooLarge { len: 10, max: 9 })
        );
        std::fs::write(&p, b"ok\xffno").unwrap();
        let e = read_to_string(&p, 100).unwrap_err();
        assert_eq!(e.to_string(), "not UTF-8 text (byte 2)");
        std::fs::remove_file(&p).unwrap();
        let e = read(&p, 100).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
        assert!(Refused::of(&e).is_none());
    }
}
