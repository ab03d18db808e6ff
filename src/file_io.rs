//! Reading and writing whole files safely: every read is bounded, every write is atomic and
//! never replaces anything but a regular file. A leaf: it uses no other module of the crate.
//!
//! # Reads
//!
//! [`read_bounded`] (and [`read_text_bounded`]) reads a whole file of one kind, with a size
//! limit per kind ([`Limit`]: [`MODEL_FILE`], [`CHECKPOINT`], [`JSON_FILE`], [`SCENE_FILE`],
//! [`IMAGE`], [`WEIGHTS_FILE`]):
//!
//! - the path, links followed, must be a regular file: a directory, a FIFO, a socket, a
//!   character or block device (a link to `/dev/zero` included), a symlink loop or a link to a
//!   missing file is refused, the error naming the file and saying what it is
//!   ([`FileError::NotRegular`]); a missing file is an [`FileError::Io`] error of kind
//!   [`std::io::ErrorKind::NotFound`] ([`FileError::is_not_found`]);
//! - its size (from the metadata of the opened file) must be within the limit, or nothing is
//!   read ([`FileError::TooLarge`]);
//! - the read itself stops one byte past the limit (`Read::take`), so a file whose metadata
//!   understates its size (`/proc`-like files) is refused too, never read until memory runs out.
//!
//! The file is opened without blocking (`O_NONBLOCK` on Linux), so a FIFO put in its place
//! between the check and the open does not hang the read; its metadata is checked again on the
//! opened file.
//!
//! # Writes
//!
//! [`write_atomic`] (and [`write_atomic_with`], [`write_atomic_staged`]) writes the content to a
//! new regular file created beside the target (`.<name>.tmp.<pid>.<n>`, never an existing file),
//! flushes it to disk and renames it over the target, so a reader sees the old file or the new
//! one, never a part; on error the temporary file is removed and the target is untouched.
//!
//! - **Links are written through**: when the path is a symbolic link (or a chain of them), the
//!   file it finally names is replaced and the link stays a link. A link to a missing file
//!   (dangling) creates the file it names.
//! - **Only regular files are replaced**: a target that exists and is not a regular file (a
//!   directory, a FIFO, a socket, a device such as `/dev/full`) is refused with
//!   [`FileError::NotWritable`] and left as it is: writing there by renaming would replace the
//!   node with a file.
//! - A replaced file keeps its permissions.
//!
//! ```
//! use bbsplat::file_io::{FileError, JSON_FILE, read_bounded, write_atomic};
//! let dir = std::env::temp_dir().join(format!("bbsplat-file-io-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! write_atomic(&dir.join("a.json"), b"{}")?;
//! assert_eq!(read_bounded(&dir.join("a.json"), JSON_FILE)?, b"{}");
//! let err = read_bounded(&dir, JSON_FILE).unwrap_err();
//! assert!(err.to_string().contains("is a directory"), "{err}");
//! std::fs::remove_dir_all(&dir).unwrap();
//! # Ok::<(), FileError>(())
//! ```

use std::fmt;
use std::fs::{self, File};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The size limit of one kind of file read whole, and its name for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    /// Largest size read, in bytes.
    pub bytes: u64,
    /// The kind of file, singular (`"model file"`): it starts the messages.
    pub what: &'static str,
    /// The kind of file, plural (`"model files"`).
    pub plural: &'static str,
}

/// The files of a model folder (`point_cloud.ply`, the texture archives): 16 GB. No fixed
/// billboard count bounds a model (the memory check of `bbsplat train` does), so the limit is
/// there against endless inputs, not to check a format: a PLY holds 240 bytes a billboard and
/// the 8-bit textures 4 bytes a texel, so 16 GB is 60 million billboards at 16×16 texels, far
/// beyond the 160 000 of the budget's largest default and beyond what trains in memory.
pub const MODEL_FILE: Limit = Limit {
    bytes: 16_000_000_000,
    what: "model file",
    plural: "model files",
};

/// Checkpoints: 64 GB. A checkpoint stores the textures as 32-bit logits with their two Adam
/// moments (12 bytes a texel channel where a model file holds 1), so it is about 12 times a
/// model's texture archives: 64 GB is 5 million billboards at 16×16 texels (with their Adam
/// state), again more than a run holds in memory.
pub const CHECKPOINT: Limit = Limit {
    bytes: 64_000_000_000,
    what: "checkpoint",
    plural: "checkpoints",
};

/// JSON documents (`bbsplat.json`, `transforms*.json`, `summary.json`, sweep grids): 256 MB.
/// A transforms file takes about 1 kB a frame: 256 MB is a quarter of a million frames.
pub const JSON_FILE: Limit = Limit {
    bytes: 256_000_000,
    what: "JSON file",
    plural: "JSON files",
};

/// The files of a COLMAP model (`cameras`, `images`, `points3D`, text or binary) and point
/// clouds: 8 GB. `images.bin` holds 24 bytes per 2-D point and `points3D.bin` about 43 bytes a
/// point plus 8 per track entry: 8 GB is some hundred million observations, more than the
/// largest photo collections COLMAP reconstructs.
pub const SCENE_FILE: Limit = Limit {
    bytes: 8_000_000_000,
    what: "scene file",
    plural: "scene files",
};

/// Images (PNG, JPEG): 1 GB, a 16-bit RGBA PNG of 11 000 × 11 000 pixels stored uncompressed.
pub const IMAGE: Limit = Limit {
    bytes: 1_000_000_000,
    what: "image",
    plural: "images",
};

/// Network weights (the LPIPS safetensors files, `crate::lpips`): 512 MB. The VGG16 file is
/// 59 MB, AlexNet's 10 MB; the limit leaves room for larger backbones, not for endless inputs.
pub const WEIGHTS_FILE: Limit = Limit {
    bytes: 512_000_000,
    what: "weights file",
    plural: "weights files",
};

/// What a path is, links followed (see [`kind_of`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FileKind {
    /// Nothing is there (no entry, and no link).
    Missing,
    /// A regular file.
    Regular,
    /// A directory.
    Directory,
    /// A symbolic link whose target does not exist.
    DanglingLink,
    /// Symbolic links that lead back to themselves (or too many of them in a row).
    SymlinkLoop,
    /// A character device (`/dev/zero`, `/dev/full`, a terminal).
    CharDevice,
    /// A block device (a disk).
    BlockDevice,
    /// A named pipe.
    Fifo,
    /// A Unix socket.
    Socket,
    /// Another kind of node.
    Other,
}

impl fmt::Display for FileKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            FileKind::Missing => "does not exist",
            FileKind::Regular => "is a regular file",
            FileKind::Directory => "is a directory",
            FileKind::DanglingLink => "is a symbolic link to a file that does not exist",
            FileKind::SymlinkLoop => "is a symlink loop (its links lead back to themselves)",
            FileKind::CharDevice => "is a character device",
            FileKind::BlockDevice => "is a block device",
            FileKind::Fifo => "is a FIFO (named pipe)",
            FileKind::Socket => "is a socket",
            FileKind::Other => "is not a regular file",
        })
    }
}

impl FileKind {
    fn of(t: fs::FileType) -> FileKind {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if t.is_char_device() {
                return FileKind::CharDevice;
            }
            if t.is_block_device() {
                return FileKind::BlockDevice;
            }
            if t.is_fifo() {
                return FileKind::Fifo;
            }
            if t.is_socket() {
                return FileKind::Socket;
            }
        }
        if t.is_file() {
            FileKind::Regular
        } else if t.is_dir() {
            FileKind::Directory
        } else {
            FileKind::Other
        }
    }
}

/// An error reading or writing a file; each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FileError {
    /// The operating system refused (a missing file included: [`FileError::is_not_found`]).
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        source: io::Error,
    },
    /// A file to read is not a regular file.
    #[error("{what} {}{}: {kind}", path.display(), link_note(path, resolved))]
    NotRegular {
        /// The path as given.
        path: PathBuf,
        /// What its links lead to (the path itself when it is no link).
        resolved: PathBuf,
        /// The kind of file expected ([`Limit::what`]).
        what: &'static str,
        /// What it is.
        kind: FileKind,
    },
    /// A file to read is larger than its kind's limit.
    #[error(
        "{what} {}: {}, more than the {} limit for {plural}",
        path.display(),
        size.map_or_else(|| "holds".to_string(), |s| format!("is {}", human_bytes(s))),
        human_bytes(*limit)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size from its metadata; `None` when the metadata said less and the read went past
        /// the limit.
        size: Option<u64>,
        /// The limit, in bytes.
        limit: u64,
        /// The kind of file ([`Limit::what`]).
        what: &'static str,
        /// Its plural ([`Limit::plural`]).
        plural: &'static str,
    },
    /// A file to write exists and is not a regular file: it is left as it is.
    #[error(
        "cannot write {}{}: it {kind}; outputs are written as a new file renamed over the path, which would replace it",
        path.display(),
        link_note(path, resolved)
    )]
    NotWritable {
        /// The path as given.
        path: PathBuf,
        /// What its links lead to (the path itself when it is no link).
        resolved: PathBuf,
        /// What it is.
        kind: FileKind,
    },
}

/// ` (a link to <target>)` when `resolved` differs from `path`.
fn link_note(path: &Path, resolved: &Path) -> String {
    if path == resolved {
        String::new()
    } else {
        format!(" (a link to {})", resolved.display())
    }
}

impl FileError {
    /// Whether the file does not exist (nothing at the path, not even a link).
    pub fn is_not_found(&self) -> bool {
        matches!(self, FileError::Io { source, .. } if source.kind() == io::ErrorKind::NotFound)
    }

    /// The path the error names, as given.
    pub fn path(&self) -> &Path {
        match self {
            FileError::Io { path, .. }
            | FileError::NotRegular { path, .. }
            | FileError::TooLarge { path, .. }
            | FileError::NotWritable { path, .. } => path,
        }
    }
}

/// Bytes in decimal units with at most one decimal (`5.2 GB`, `16 GB`, `740 bytes`).
fn human_bytes(bytes: u64) -> String {
    let units = [(1e12, "TB"), (1e9, "GB"), (1e6, "MB"), (1e3, "kB")];
    for (scale, unit) in units {
        let b = bytes as f64;
        if b >= scale {
            let text = format!("{:.1}", b / scale);
            return format!("{} {unit}", text.strip_suffix(".0").unwrap_or(&text));
        }
    }
    format!("{bytes} bytes")
}

/// Whether `e` says "too many levels of symbolic links".
fn is_loop(e: &io::Error) -> bool {
    #[cfg(target_os = "linux")]
    {
        e.raw_os_error() == Some(libc::ELOOP)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = e;
        false
    }
}

/// What `path` is, links followed: a dangling link and a symlink loop are kinds of their own,
/// not "missing".
///
/// # Errors
/// What the file system reports other than "not found" and "a loop" (permission denied, a
/// component that is a file, …).
pub fn kind_of(path: &Path) -> io::Result<FileKind> {
    match fs::metadata(path) {
        Ok(m) => Ok(FileKind::of(m.file_type())),
        Err(e) if is_loop(&e) => Ok(FileKind::SymlinkLoop),
        Err(e) if e.kind() == io::ErrorKind::NotFound => match fs::symlink_metadata(path) {
            Ok(m) if m.file_type().is_symlink() => Ok(FileKind::DanglingLink),
            _ => Ok(FileKind::Missing),
        },
        Err(e) => Err(e),
    }
}

/// Whether `path` names something a reader should try to read as a file: anything but nothing
/// and a directory (so a device, a FIFO, a loop or a dangling link is read, and refused with
/// what it is, instead of being reported missing). An error asking counts as a file, for the
/// read to report it.
pub fn names_a_file(path: &Path) -> bool {
    !matches!(kind_of(path), Ok(FileKind::Missing | FileKind::Directory))
}

/// Longest chain of links followed (Linux's limit).
const MAX_LINKS: usize = 40;

/// `path` with its final symbolic links followed, one after the other, as the system follows
/// them (a relative target is relative to the link's folder); folders along the way are left to
/// the system. The path itself when it is no link (or does not exist).
///
/// # Errors
/// [`FileError::NotWritable`] with [`FileKind::SymlinkLoop`] after 40 links in a row;
/// [`FileError::Io`] when a link cannot be read.
pub fn resolve_links(path: &Path) -> Result<PathBuf, FileError> {
    let mut at = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&at) {
            Ok(m) if m.file_type().is_symlink() => {
                let target = fs::read_link(&at).map_err(io_error(&at, "reading the link"))?;
                at = match at.parent() {
                    Some(dir) if target.is_relative() => dir.join(target),
                    _ => target,
                };
            }
            _ => return Ok(at),
        }
    }
    Err(FileError::NotWritable {
        path: path.to_path_buf(),
        resolved: path.to_path_buf(),
        kind: FileKind::SymlinkLoop,
    })
}

fn io_error<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(io::Error) -> FileError + 'a {
    move |source| FileError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
}

/// The error for reading `path` (expected: a `what`), which is a `kind`.
pub fn not_regular(path: &Path, what: &'static str, kind: FileKind) -> FileError {
    FileError::NotRegular {
        path: path.to_path_buf(),
        resolved: resolve_links(path).unwrap_or_else(|_| path.to_path_buf()),
        what,
        kind,
    }
}

/// Checks that `path` is a regular file of at most `limit` bytes (links followed) and returns
/// its size, without reading it: [`read_bounded`]'s checks, for a file read later.
///
/// # Errors
/// As [`read_bounded`].
pub fn check_readable(path: &Path, limit: Limit) -> Result<u64, FileError> {
    check_kind(path, limit)?;
    let size = fs::metadata(path)
        .map_err(io_error(path, "reading its metadata"))?
        .len();
    check_size(path, size, limit)?;
    Ok(size)
}

fn check_kind(path: &Path, limit: Limit) -> Result<(), FileError> {
    match kind_of(path).map_err(io_error(path, "opening"))? {
        FileKind::Regular => Ok(()),
        FileKind::Missing => Err(io_error(path, "opening")(io::Error::from(io::ErrorKind::NotFound))),
        kind => Err(not_regular(path, limit.what, kind)),
    }
}

fn check_size(path: &Path, size: u64, limit: Limit) -> Result<(), FileError> {
    if size > limit.bytes {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
            size: Some(size),
            limit: limit.bytes,
            what: limit.what,
            plural: limit.plural,
        });
    }
    Ok(())
}

/// Opens `path` for reading without blocking on a FIFO (Linux: `O_NONBLOCK`, which regular
/// files ignore).
fn open_for_reading(path: &Path) -> io::Result<File> {
    let mut options = fs::OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

/// Reads the whole regular file `path`, of at most `limit` bytes: see the [module
/// documentation](self).
///
/// # Errors
/// [`FileError::NotRegular`] (with what the file is), [`FileError::TooLarge`], or
/// [`FileError::Io`] (a missing file: [`FileError::is_not_found`]).
pub fn read_bounded(path: &Path, limit: Limit) -> Result<Vec<u8>, FileError> {
    check_kind(path, limit)?;
    let file = open_for_reading(path).map_err(io_error(path, "opening"))?;
    let meta = file.metadata().map_err(io_error(path, "reading its metadata"))?;
    let kind = FileKind::of(meta.file_type());
    if kind != FileKind::Regular {
        return Err(not_regular(path, limit.what, kind));
    }
    check_size(path, meta.len(), limit)?;
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(meta.len() as usize)
        .map_err(|e| io_error(path, "allocating memory for it")(io::Error::new(io::ErrorKind::OutOfMemory, e)))?;
    file.take(limit.bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(io_error(path, "reading"))?;
    if bytes.len() as u64 > limit.bytes {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
            size: None,
            limit: limit.bytes,
            what: limit.what,
            plural: limit.plural,
        });
    }
    Ok(bytes)
}

/// `bytes` without a leading UTF-8 byte-order mark (`EF BB BF`, which Windows editors write at
/// the start of text files; JSON readers may ignore it, RFC 8259 §8.1).
///
/// ```
/// assert_eq!(bbsplat::file_io::without_bom(b"\xEF\xBB\xBF{}"), b"{}");
/// assert_eq!(bbsplat::file_io::without_bom(b"{}"), b"{}");
/// ```
pub fn without_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// [`read_bounded`], the content as UTF-8 text, a leading byte-order mark left out
/// ([`without_bom`]).
///
/// # Errors
/// As [`read_bounded`]; [`FileError::Io`] of kind [`io::ErrorKind::InvalidData`] when the file is
/// not UTF-8.
pub fn read_text_bounded(path: &Path, limit: Limit) -> Result<String, FileError> {
    let mut bytes = read_bounded(path, limit)?;
    let bom = bytes.len() - without_bom(&bytes).len();
    bytes.drain(..bom);
    String::from_utf8(bytes)
        .map_err(|e| io_error(path, "reading it as text")(io::Error::new(io::ErrorKind::InvalidData, e)))
}

/// Writes `bytes` to `path` atomically: see the [module documentation](self).
///
/// # Errors
/// [`FileError::NotWritable`] when `path` (links followed) exists and is not a regular file;
/// [`FileError::Io`] naming the step that failed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// [`write_atomic`], the content written by `write` into the temporary file (which it must not
/// leave partly buffered: flush any buffer it wraps around the file).
///
/// # Errors
/// As [`write_atomic`].
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&mut File) -> io::Result<()>) -> Result<(), FileError> {
    write_atomic_staged(path, write, |_| {})
}

/// The stages of an atomic write, in order, as [`write_atomic_staged`] reports them: the
/// temporary file created, written, flushed to disk, renamed over the target.
pub const WRITE_STAGES: [&str; 4] = ["created", "written", "synced", "renamed"];

/// [`write_atomic_with`], calling `stage` after each of [`WRITE_STAGES`] (a test's hook to stop
/// the process there).
///
/// # Errors
/// As [`write_atomic`].
pub fn write_atomic_staged(
    path: &Path,
    write: impl FnOnce(&mut File) -> io::Result<()>,
    mut stage: impl FnMut(&'static str),
) -> Result<(), FileError> {
    let target = resolve_links(path)?;
    let existing = match fs::symlink_metadata(&target) {
        Ok(m) if m.is_file() => Some(m.permissions()),
        Ok(m) => {
            return Err(FileError::NotWritable {
                path: path.to_path_buf(),
                resolved: target,
                kind: FileKind::of(m.file_type()),
            });
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => None,
        Err(e) => return Err(io_error(path, "reading its metadata")(e)),
    };
    let name = target.file_name().ok_or_else(|| {
        io_error(path, "choosing the temporary file")(io::Error::new(
            io::ErrorKind::InvalidInput,
            "the path has no file name",
        ))
    })?;
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Unique per process and per call, so concurrent writes of one process do not share a file.
    static WRITES: AtomicU64 = AtomicU64::new(0);
    let serial = WRITES.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(
        ".{}.tmp.{}.{serial}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let io = |action| io_error(path, action);
    let result = (|| {
        let mut f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(io("creating the temporary file"))?;
        stage(WRITE_STAGES[0]);
        if let Some(permissions) = existing {
            f.set_permissions(permissions)
                .map_err(io("giving the temporary file the permissions of the file it replaces"))?;
        }
        write(&mut f).map_err(io("writing"))?;
        stage(WRITE_STAGES[1]);
        f.sync_all().map_err(io("flushing to disk"))?;
        stage(WRITE_STAGES[2]);
        drop(f);
        fs::rename(&tmp, &target).map_err(io("renaming the temporary file"))?;
        stage(WRITE_STAGES[3]);
        Ok(())
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    fn temp(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bbsplat-file-io-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    const SMALL: Limit = Limit {
        bytes: 8,
        what: "test file",
        plural: "test files",
    };

    #[test]
    fn kinds_are_told_apart() {
        let dir = temp("kinds");
        let (file, link, dangling, a, b) = (
            dir.join("f"),
            dir.join("l"),
            dir.join("d"),
            dir.join("a"),
            dir.join("b"),
        );
        fs::write(&file, b"x").unwrap();
        std::os::unix::fs::symlink(&file, &link).unwrap();
        std::os::unix::fs::symlink(dir.join("nothing"), &dangling).unwrap();
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        assert_eq!(kind_of(&file).unwrap(), FileKind::Regular);
        assert_eq!(kind_of(&link).unwrap(), FileKind::Regular);
        assert_eq!(kind_of(&dir).unwrap(), FileKind::Directory);
        assert_eq!(kind_of(&dir.join("nothing")).unwrap(), FileKind::Missing);
        assert_eq!(kind_of(&dangling).unwrap(), FileKind::DanglingLink);
        assert_eq!(kind_of(&a).unwrap(), FileKind::SymlinkLoop);
        assert_eq!(kind_of(Path::new("/dev/null")).unwrap(), FileKind::CharDevice);
        assert!(names_a_file(&a) && names_a_file(&dangling) && !names_a_file(&dir));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn reads_are_bounded_and_refuse_what_is_not_a_file() {
        let dir = temp("reads");
        let file = dir.join("f");
        fs::write(&file, b"12345678").unwrap();
        assert_eq!(read_bounded(&file, SMALL).unwrap(), b"12345678");
        fs::write(&file, b"123456789").unwrap();
        let err = read_bounded(&file, SMALL).unwrap_err();
        assert!(matches!(err, FileError::TooLarge { size: Some(9), .. }), "{err}");
        assert!(
            err.to_string().contains("is 9 bytes, more than the 8 bytes limit"),
            "{err}"
        );
        let err = read_bounded(Path::new("/dev/zero"), SMALL).unwrap_err();
        assert!(err.to_string().contains("is a character device"), "{err}");
        // /proc files say 0 bytes: the read stops past the limit.
        let big = Limit { bytes: 16, ..SMALL };
        let err = read_bounded(Path::new("/proc/self/maps"), big).unwrap_err();
        assert!(matches!(err, FileError::TooLarge { size: None, .. }), "{err}");
        let err = read_bounded(&dir.join("none"), SMALL).unwrap_err();
        assert!(err.is_not_found() && err.to_string().contains("none"), "{err}");
        assert_eq!(check_readable(&file, Limit { bytes: 9, ..SMALL }).unwrap(), 9);
        assert!(read_text_bounded(&file, Limit { bytes: 9, ..SMALL }).unwrap() == "123456789");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn writes_go_through_links_and_refuse_nodes() {
        let dir = temp("writes");
        let (file, link) = (dir.join("f"), dir.join("l"));
        fs::write(&file, b"old").unwrap();
        std::os::unix::fs::symlink("f", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(fs::read(&file).unwrap(), b"new");
        // A dangling link creates the file it names.
        let dangling = dir.join("d");
        std::os::unix::fs::symlink(dir.join("made"), &dangling).unwrap();
        write_atomic(&dangling, b"made").unwrap();
        assert_eq!(fs::read(dir.join("made")).unwrap(), b"made");
        let err = write_atomic(&dir, b"x").unwrap_err();
        assert!(
            matches!(
                err,
                FileError::NotWritable {
                    kind: FileKind::Directory,
                    ..
                }
            ),
            "{err}"
        );
        let err = write_atomic(Path::new("/dev/null"), b"x").unwrap_err();
        assert!(err.to_string().contains("is a character device"), "{err}");
        let mut stages = Vec::new();
        write_atomic_staged(&file, |f| f.write_all(b"x"), |s| stages.push(s)).unwrap();
        assert_eq!(stages, WRITE_STAGES);
        let names: Vec<_> = fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 4, "no temporary file left: {names:?}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(human_bytes(740), "740 bytes");
        assert_eq!(human_bytes(16_000_000_000), "16 GB");
        assert_eq!(human_bytes(5_240_000_000), "5.2 GB");
    }
}
