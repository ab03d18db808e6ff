//! Typed errors of the scene loader.
//!
//! Every error names the file it concerns and, where the problem is inside the file, the record
//! (a 1-based line of a text file, a record and byte offset of a binary file, or a path inside a
//! JSON document), and says what is wrong. Messages are meant to be shown to users as they are.

use crate::file_io::FileError;
use std::fmt;
use std::path::{Path, PathBuf};

/// Where inside a file a problem was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// The file as a whole (a problem with its header, its size or its encoding).
    File,
    /// A 1-based line of a text file.
    Line(usize),
    /// A record of a binary file, e.g. `image 3 (image_id 7)`, and the byte offset (from the
    /// start of the file) where the problem was detected.
    Binary {
        /// The record being read, in words.
        record: String,
        /// Byte offset from the start of the file.
        offset: u64,
    },
    /// A named record of a parsed model, e.g. `image 3 (image_id 7, "0003.jpg")`, or a path
    /// inside a JSON document such as `frames[3].transform_matrix`.
    Record(String),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::File => write!(f, "whole file"),
            Location::Line(n) => write!(f, "line {n}"),
            Location::Binary { record, offset } => write!(f, "{record}, byte offset {offset}"),
            Location::Record(r) => write!(f, "{r}"),
        }
    }
}

/// An error while loading a scene. The `Display` text is complete (file, record, problem).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// A file could not be read (or written).
    #[error("{}: cannot access file: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// A record of a file is malformed or holds an invalid value.
    #[error("{}: {location}: {message}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// The record or line.
        location: Location,
        /// What is wrong.
        message: String,
    },
    /// A camera uses a model this loader does not handle. `model` is the COLMAP name when
    /// known, with its numeric id for binary files (e.g. `OPENCV_FISHEYE (model id 5)` or
    /// `unknown model id 42`).
    #[error(
        "{}: {location}: unsupported camera model {model}; supported models are SIMPLE_PINHOLE, PINHOLE, \
         SIMPLE_RADIAL, RADIAL and OPENCV (undistort other models with COLMAP's image_undistorter first)",
        file.display()
    )]
    UnsupportedCameraModel {
        /// The file.
        file: PathBuf,
        /// The record or line.
        location: Location,
        /// The model's name and/or id.
        model: String,
    },
    /// A JSON document is not valid JSON.
    #[error("{}: malformed JSON at line {line}, column {column}: {message}", file.display())]
    Json {
        /// The file.
        file: PathBuf,
        /// 1-based line of the syntax error.
        line: usize,
        /// 1-based column of the syntax error.
        column: usize,
        /// The parser's description.
        message: String,
    },
    /// An image referenced by a record does not exist.
    #[error("{}: {location}: image file {} does not exist", file.display(), image.display())]
    MissingImage {
        /// The file holding the reference (e.g. `images.bin`).
        file: PathBuf,
        /// The record referencing the image.
        location: Location,
        /// The image path that was looked for.
        image: PathBuf,
    },
    /// An image file exists but cannot be decoded.
    #[error("{}: cannot decode image referenced by {} ({location}): {message}", image.display(), file.display())]
    ImageDecode {
        /// The image file.
        image: PathBuf,
        /// The file holding the reference.
        file: PathBuf,
        /// The referencing record.
        location: Location,
        /// The decoder's description.
        message: String,
    },
    /// An image decoded on demand ([`super::on_demand`]) no longer gives the pixels it gave when
    /// the scene was loaded: its file was edited or replaced since.
    #[error("{}: the image changed on disk since the scene was loaded: {message}", image.display())]
    ImageChanged {
        /// The image file.
        image: PathBuf,
        /// What differs.
        message: String,
    },
    /// An image's size differs from its camera's.
    #[error(
        "{}: image is {}x{} pixels but its camera in {} ({location}) is {}x{}",
        image.display(), actual.0, actual.1, file.display(), expected.0, expected.1
    )]
    ImageSize {
        /// The image file.
        image: PathBuf,
        /// Width and height of the decoded image.
        actual: (u64, u64),
        /// Width and height stated by the camera.
        expected: (u64, u64),
        /// The file holding the camera.
        file: PathBuf,
        /// The camera or frame record.
        location: Location,
    },
    /// No mask for an image in the mask folder ([`crate::scene::LoadOptions::masks_dir`], or a
    /// NeuS dataset's `mask/`).
    #[error(
        "{}: no mask for this image in {} (looked for the image's stem with .png, .jpg or .jpeg, and the same number with other leading zeros)",
        image.display(), masks_dir.display()
    )]
    MissingMask {
        /// The image.
        image: PathBuf,
        /// The mask folder.
        masks_dir: PathBuf,
    },
    /// An `.npy` array or `.npz` archive of a dataset is malformed or of a kind not read
    /// ([`crate::scene::npy::NpyError`]).
    #[error("{}: {}{problem}", file.display(), array.as_ref().map_or(String::new(), |a| format!("array {a:?}: ")))]
    Npy {
        /// The `.npy` or `.npz` file.
        file: PathBuf,
        /// The member of an `.npz` archive, when the problem is in one.
        array: Option<String>,
        /// What is wrong.
        problem: crate::scene::npy::NpyError,
    },
    /// A dataset holds no usable view (or no training view after the split).
    #[error("{}: empty dataset: {reason}", path.display())]
    Empty {
        /// The dataset file or folder.
        path: PathBuf,
        /// Why no view is usable.
        reason: String,
    },
    /// No known dataset layout was found in a folder.
    #[error("{}: no dataset found: {looked_for}", path.display())]
    NotDetected {
        /// The folder.
        path: PathBuf,
        /// What was looked for.
        looked_for: String,
    },
    /// An option of [`crate::scene::LoadOptions`] is invalid.
    #[error("invalid load option: {0}")]
    InvalidOption(String),
    /// A file is not one to read: not a regular file (a device, a FIFO, a symlink loop, a link
    /// to a missing file) or larger than its kind's limit ([`crate::file_io::SCENE_FILE`],
    /// [`crate::file_io::JSON_FILE`], [`crate::file_io::IMAGE`]); or an output that exists and is
    /// not a regular file.
    #[error(transparent)]
    File(FileError),
}

/// An operating-system error is [`SceneError::Io`]; the rest is [`SceneError::File`].
impl From<FileError> for SceneError {
    fn from(e: FileError) -> Self {
        match e {
            FileError::Io { path, source, .. } => SceneError::Io { path, source },
            other => SceneError::File(other),
        }
    }
}

impl SceneError {
    /// A [`SceneError::Parse`] error.
    pub(crate) fn parse(file: &Path, location: Location, message: impl Into<String>) -> Self {
        SceneError::Parse {
            file: file.to_path_buf(),
            location,
            message: message.into(),
        }
    }

    /// A [`SceneError::Io`] error.
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        SceneError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
