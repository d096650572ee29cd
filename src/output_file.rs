//! Writing the files a command produces: only over a regular file, never through a symlink, never
//! a partial file left looking complete.
//!
//! The output-side counterpart of [`crate::regular_file`]. Every file a tool writes goes through
//! here, because a plain `File::create` or `std::fs::write` at a user-given path
//!
//! - writes *into* a device (`-o /dev/sda` on a robot computer run as root), blocks on a FIFO,
//! - and a "temporary file + rename" replaces a device node (`/dev/null`, `/dev/full`) or a symlink
//!   (`current.fwt -> v1.fwt`) with a plain file, reporting success;
//! - leaves a truncated file under the final name when the process is stopped or the disk is full.
//!
//! [`check`] refuses a path that exists and is not a regular file (device, FIFO, socket, directory)
//! or is a symbolic link, naming what it is; commands call it on every output before any work.
//! [`AtomicFile`] writes a temporary file in the destination's directory (hidden name
//! `.tmp-PID-N.NAME`), and on [`AtomicFile::commit`] flushes it, `fsync`s it, checks the destination
//! again, renames it over the destination and `fsync`s the directory. Dropped without a commit (an
//! error, a panic), it removes the temporary file: the destination keeps its previous content. A
//! process killed mid-write leaves at most the hidden temporary file, never a partial destination.
//!
//! A symlink at the output path is refused by default, with an error that names its target (write
//! to the target to replace it); [`Symlinks::Follow`] replaces the link's final target instead,
//! keeping the link. A replaced regular file keeps its permission bits.
//!
//! Like `std::fs`, the messages do not repeat the destination path: the caller names it. A refusal
//! carries an [`OutputRefused`] (reach it with [`OutputRefused::of`]).
//!
//! ```
//! use frictionless::output_file;
//! let err = output_file::write(std::path::Path::new("/dev/null"), b"x").unwrap_err();
//! assert_eq!(
//!     err.to_string(),
//!     "exists and is not a regular file (character device); refusing to replace it (nothing was written)"
//! );
//! ```

use std::ffi::OsString;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::regular_file::file_type_name;

/// Why an output path was refused before anything was written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OutputRefused {
    /// The path exists and is not a regular file: a device, a FIFO, a socket or a directory.
    NotRegular {
        /// What it is, e.g. "character device", "FIFO", "directory".
        file_type: &'static str,
    },
    /// The path is a symbolic link and following it was not asked for.
    Symlink {
        /// Where the link points (as stored in the link).
        target: PathBuf,
    },
    /// The path has no file name (`/`, `..`, empty).
    NoFileName,
}

impl OutputRefused {
    /// The refusal inside an error from this module (`None` for an OS error such as "permission
    /// denied" or "no space left on device").
    pub fn of(e: &io::Error) -> Option<&OutputRefused> {
        e.get_ref()
            .and_then(|inner| inner.downcast_ref::<OutputRefused>())
    }

    fn into_io(self) -> io::Error {
        io::Error::new(io::ErrorKind::InvalidInput, self)
    }
}

impl std::fmt::Display for OutputRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OutputRefused::NotRegular { file_type } => write!(
                f,
                "exists and is not a regular file ({file_type}); refusing to replace it (nothing was written)"
            ),
            OutputRefused::Symlink { target } => write!(
                f,
                "is a symbolic link to {}; refusing to write through it (nothing was written): name the target itself to replace it",
                target.display()
            ),
            OutputRefused::NoFileName => write!(f, "has no file name"),
        }
    }
}

impl std::error::Error for OutputRefused {}

/// What to do with a symbolic link at the output path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Symlinks {
    /// Refuse it ([`OutputRefused::Symlink`]): the default.
    #[default]
    Refuse,
    /// Replace the file the link finally points to (atomically, in the target's directory); the link
    /// itself stays. The target must be a regular file or not exist.
    Follow,
}

/// Checks that `path` may be written as an output: it does not exist, or it is a regular file (a
/// symbolic link is refused, see [`Symlinks`]). Returns the path that will actually be replaced (the
/// link's final target with [`Symlinks::Follow`], else `path`).
pub fn check_with(path: &Path, symlinks: Symlinks) -> io::Result<PathBuf> {
    if path.file_name().is_none() {
        return Err(OutputRefused::NoFileName.into_io());
    }
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(path.to_owned()),
        Err(e) => Err(e),
        Ok(m) if m.file_type().is_file() => Ok(path.to_owned()),
        Ok(m) if m.file_type().is_symlink() => match symlinks {
            Symlinks::Refuse => Err(OutputRefused::Symlink {
                target: std::fs::read_link(path)?,
            }
            .into_io()),
            Symlinks::Follow => {
                let target = resolve_link(path)?;
                check_with(&target, Symlinks::Refuse)
            }
        },
        Ok(m) => Err(OutputRefused::NotRegular {
            file_type: file_type_name(m.file_type()),
        }
        .into_io()),
    }
}

/// [`check_with`] with the default: a symbolic link is refused.
pub fn check(path: &Path) -> io::Result<()> {
    check_with(path, Symlinks::Refuse).map(drop)
}

/// The final target of the symlink `path` (a dangling one included), absolute or relative to the
/// current directory.
fn resolve_link(path: &Path) -> io::Result<PathBuf> {
    let mut p = path.to_owned();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let t = std::fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) if t.is_relative() => dir.join(t),
                    _ => t,
                };
            }
            _ => return Ok(p),
        }
    }
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        "too many levels of symbolic links",
    ))
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// An output file being written: a hidden temporary file beside the destination, renamed over it by
/// [`AtomicFile::commit`] and removed when dropped without a commit. Writes are buffered.
#[derive(Debug)]
pub struct AtomicFile {
    file: Option<BufWriter<File>>,
    tmp: PathBuf,
    dest: PathBuf,
}

impl AtomicFile {
    /// Starts writing `path` (refused as by [`check`]).
    pub fn create(path: &Path) -> io::Result<Self> {
        Self::create_with(path, Symlinks::Refuse)
    }

    /// Starts writing `path`, a symbolic link there handled as `symlinks` says.
    pub fn create_with(path: &Path, symlinks: Symlinks) -> io::Result<Self> {
        let dest = check_with(path, symlinks)?;
        let name = dest
            .file_name()
            .ok_or_else(|| OutputRefused::NoFileName.into_io())?;
        // Hidden, and ending in the destination's own extension (a writer that picks the format
        // by extension, e.g. a PNG encoder, still works on it).
        let mut tmp_name = OsString::from(format!(
            ".tmp-{}-{}.",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        tmp_name.push(name);
        let tmp = dest.with_file_name(tmp_name);
        let mut opts = std::fs::OpenOptions::new();
        opts.write(true).create_new(true);
        // A replaced file keeps its permission bits (a model made group-readable stays so).
        let mode = std::fs::metadata(&dest)
            .ok()
            .map(|m| m.permissions().mode() & 0o7777);
        if let Some(mode) = mode {
            opts.mode(mode);
        }
        let file = opts.open(&tmp).map_err(|e| {
            io::Error::new(
                e.kind(),
                format!("cannot create a temporary file in its directory: {e}"),
            )
        })?;
        if let Some(mode) = mode {
            // The umask applies to the mode given to `open`; set it exactly.
            let _ = file.set_permissions(std::fs::Permissions::from_mode(mode));
        }
        Ok(Self {
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            tmp,
            dest,
        })
    }

    /// The path that [`AtomicFile::commit`] replaces.
    pub fn destination(&self) -> &Path {
        &self.dest
    }

    /// Flushes and `fsync`s the file, checks the destination is still a regular file or absent,
    /// renames the file over it and `fsync`s the directory. On error the temporary file is removed
    /// and the destination is as before.
    pub fn commit(mut self) -> io::Result<()> {
        self.sync()?;
        check_with(&self.dest, Symlinks::Refuse)?;
        std::fs::rename(&self.tmp, &self.dest)?;
        // Renamed: nothing for Drop to remove.
        self.tmp = PathBuf::new();
        sync_dir(&self.dest)
    }

    /// Flushes, `fsync`s and closes the temporary file (done by [`AtomicFile::commit`] if not yet).
    fn sync(&mut self) -> io::Result<()> {
        if let Some(w) = self.file.take() {
            let file = w.into_inner().map_err(|e| e.into_error())?;
            file.sync_all()?;
        }
        Ok(())
    }

    fn writer(&mut self) -> io::Result<&mut BufWriter<File>> {
        self.file
            .as_mut()
            .ok_or_else(|| io::Error::other("output file already closed"))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer()?.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.writer()?.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.writer()?.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.tmp.as_os_str().is_empty() {
            drop(self.file.take());
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// `fsync` of the directory holding `path`, so a rename in it survives a power loss. A filesystem
/// that cannot sync a directory (EINVAL) is not an error.
fn sync_dir(path: &Path) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let d = File::open(dir)?;
    match d.sync_all() {
        Err(e) if e.raw_os_error() == Some(libc::EINVAL) => Ok(()),
        r => r,
    }
}

/// Writes `bytes` to `path` atomically (see [`AtomicFile`]).
pub fn write(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    let mut f = AtomicFile::create(path.as_ref())?;
    f.write_all(bytes.as_ref())?;
    f.commit()
}

/// Creates (or truncates) `path` and opens it for writing in place, refused as by [`check`]: only
/// for a log meant to be read while it grows (a child process's output), never for a result, which
/// goes through [`AtomicFile`]. Opened without following a symlink and without blocking on a FIFO
/// swapped in after the check; the opened file is checked to be a regular file again.
pub fn create_log(path: &Path) -> io::Result<File> {
    open_checked(path, false)
}

/// Opens `path` for appending (created if absent, mode 0o666 less the umask), refused as by
/// [`check`]: for logs that grow line by line (each line one `write`, complete or absent). The open
/// does not follow a symlink and does not block on a FIFO swapped in after the check; the opened file
/// is checked to be a regular file again.
pub fn open_append(path: &Path) -> io::Result<File> {
    open_checked(path, true)
}

fn open_checked(path: &Path, append: bool) -> io::Result<File> {
    check(path)?;
    let mut opts = std::fs::OpenOptions::new();
    opts.create(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK);
    if append {
        opts.append(true);
    } else {
        opts.write(true).truncate(true);
    }
    let file = opts.open(path)?;
    let t = file.metadata()?.file_type();
    if !t.is_file() {
        return Err(OutputRefused::NotRegular {
            file_type: file_type_name(t),
        }
        .into_io());
    }
    Ok(file)
}

/// Writes `path` atomically with a writer that takes a path rather than a stream (e.g. a PNG
/// backend): `write` gets the path of a fresh temporary file beside `path` (same extension), which is
/// then synced and renamed over `path` as by [`AtomicFile::commit`]; on error it is removed. An error
/// of `write` is returned as an [`io::Error`] carrying its text.
pub fn write_by_path<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.sync()?;
    write(&f.tmp).map_err(|e| io::Error::other(e.to_string()))?;
    File::open(&f.tmp)?.sync_all()?;
    f.commit()
}

/// Replaces a set of files as one step: `data` (e.g. a dataset CSV) and `marker`, the file that
/// says the set is complete (e.g. its sidecar, which records the row count). All must be fully
/// written already; all are flushed and synced before anything is renamed. The marker's previous version is removed first,
/// then the data files are renamed, then the marker: a process stopped in between leaves new data
/// *without* a marker, never new data beside the old marker or old data beside the new one.
pub fn commit_with_marker(mut data: Vec<AtomicFile>, mut marker: AtomicFile) -> io::Result<()> {
    for f in &mut data {
        f.sync()?;
    }
    marker.sync()?;
    check_with(&marker.dest, Symlinks::Refuse)?;
    for f in &data {
        check_with(&f.dest, Symlinks::Refuse)?;
    }
    match std::fs::remove_file(&marker.dest) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
        _ => {}
    }
    for f in data {
        f.commit()?;
    }
    marker.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("frictionless-of-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn replaces_a_regular_file_and_keeps_its_mode() {
        let d = tmpdir("regular");
        let p = d.join("a.txt");
        std::fs::write(&p, b"old").unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o640)).unwrap();
        write(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        assert_eq!(
            std::fs::metadata(&p).unwrap().permissions().mode() & 0o777,
            0o640
        );
        assert_eq!(entries(&d), ["a.txt"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_device_a_fifo_and_a_directory_are_refused() {
        let e = write(Path::new("/dev/null"), b"x").unwrap_err();
        assert_eq!(
            OutputRefused::of(&e),
            Some(&OutputRefused::NotRegular {
                file_type: "character device"
            })
        );
        let d = tmpdir("fifo");
        let p = d.join("f");
        let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = write(&p, b"x").unwrap_err();
        assert_eq!(
            OutputRefused::of(&e),
            Some(&OutputRefused::NotRegular { file_type: "FIFO" })
        );
        let e = write(&d, b"x").unwrap_err();
        assert_eq!(
            OutputRefused::of(&e),
            Some(&OutputRefused::NotRegular {
                file_type: "directory"
            })
        );
        assert_eq!(entries(&d), ["f"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_symlink_is_refused_unless_followed() {
        let d = tmpdir("link");
        let target = d.join("v1.fwt");
        std::fs::write(&target, b"v1").unwrap();
        let link = d.join("current.fwt");
        std::os::unix::fs::symlink("v1.fwt", &link).unwrap();
        let e = write(&link, b"v2").unwrap_err();
        assert_eq!(
            OutputRefused::of(&e),
            Some(&OutputRefused::Symlink {
                target: "v1.fwt".into()
            })
        );
        assert!(e.to_string().contains("symbolic link to v1.fwt"), "{e}");
        assert_eq!(std::fs::read(&target).unwrap(), b"v1");
        let mut f = AtomicFile::create_with(&link, Symlinks::Follow).unwrap();
        f.write_all(b"v2").unwrap();
        f.commit().unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"v2");
        // A link to a device is refused even when followed.
        let dev = d.join("null");
        std::os::unix::fs::symlink("/dev/null", &dev).unwrap();
        assert!(AtomicFile::create_with(&dev, Symlinks::Follow).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn dropped_without_commit_leaves_the_old_file_and_no_temporary() {
        let d = tmpdir("drop");
        let p = d.join("data.csv");
        std::fs::write(&p, b"old complete").unwrap();
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.write_all(b"partial").unwrap();
            assert_eq!(entries(&d).len(), 2);
        }
        assert_eq!(std::fs::read(&p).unwrap(), b"old complete");
        assert_eq!(entries(&d), ["data.csv"]);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
