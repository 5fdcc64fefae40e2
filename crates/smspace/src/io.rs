//! Reading and writing the interchange files: `.npy` arrays and JSON documents.
//!
//! Every array smspace writes is a little-endian `float64` (or `int64` for indices)
//! `.npy` file in C order, so that `numpy.load` reads it as is. The shapes are:
//!
//! | file | shape | meaning |
//! |---|---|---|
//! | motors | `(M, N)` | explored motor configurations, radians |
//! | poses | `(M, 3)` | observer's retina pose `(x, y, alpha)` |
//! | kernel sets | `(M, P, N)` | `P` points of every set `M^i` |
//! | distances | `(M, M)` | set metric |
//! | embeddings | `(M, d)` | coordinates |
//!
//! Writes are atomic: the bytes go to a temporary file in the destination folder,
//! which is then renamed over the destination, so an interrupted run never leaves a
//! truncated file where a good one stood.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, ArrayBase, ArrayD, Data, Dimension, Ix2, Ix3};
use ndarray_npy::{ReadNpyError, ReadNpyExt, ReadableElement, WritableElement, WriteNpyExt};
use serde::de::DeserializeOwned;
use serde::Serialize;

/// Errors of reading and writing files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The file could not be opened or read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The file is not a `.npy` array of the expected element type.
    #[error("{path} is not a readable .npy array of float64: {reason} (save it with numpy.save(path, array.astype(numpy.float64)))")]
    Npy {
        /// The file.
        path: PathBuf,
        /// What the reader found.
        reason: String,
    },
    /// The file is not a whole `.npy` file: too short for its header, or a header whose
    /// shape does not match the bytes that follow it.
    #[error("{path} is not a complete .npy file: {reason}; it may be truncated (an interrupted copy or write): write it again with numpy.save")]
    Incomplete {
        /// The file.
        path: PathBuf,
        /// What does not fit, with the sizes.
        reason: String,
    },
    /// The array has the wrong number of dimensions or the wrong extent.
    #[error("{path} has shape {found}, expected {expected}")]
    Shape {
        /// The file.
        path: PathBuf,
        /// The shape found, as `(a, b, c)`.
        found: String,
        /// The shape expected, with symbols, e.g. `(M, 4)`.
        expected: String,
    },
    /// The array holds NaN or an infinity.
    #[error("{path} holds a non-finite value ({value}) at index {index}; every entry must be a finite number")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The offending multi-index, as `[i, j]`.
        index: String,
        /// The value found.
        value: f64,
    },
    /// The file is not valid JSON for the expected document.
    #[error("{path} is not a valid {what} file: {reason}")]
    Json {
        /// The file.
        path: PathBuf,
        /// What the document should have been (e.g. "environment").
        what: &'static str,
        /// The parser's reason, with line and column.
        reason: serde_json::Error,
    },
    /// An entry of the array is not one of the values it may hold.
    #[error("{path} is not a valid {what} file: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What the array should have been (e.g. "closed/open record").
        what: &'static str,
        /// Which entry, its value and the values allowed.
        reason: String,
    },
    /// An array to be written holds NaN or an infinity: nothing is written.
    #[error("refusing to write {path}: its entry {index} is {value}, and smspace never writes a non-finite number (the computation that made it overflowed or failed; check the inputs' scale, or report it with them)")]
    NonFiniteOutput {
        /// The file that was not written.
        path: PathBuf,
        /// The first offending multi-index, as `[i, j]`.
        index: String,
        /// The value found.
        value: f64,
    },
    /// An output names one of the command's input files: writing it would replace the
    /// input.
    #[error("refusing to write {output}: it is the input {what} {input}, which writing would replace; write the output elsewhere (another --out, or another run folder) and nothing is lost")]
    OutputIsInput {
        /// The output that was not written.
        output: PathBuf,
        /// The input it names (the same file by path, link or inode).
        input: PathBuf,
        /// Which input it is (e.g. `--motors`, `[data] sensors`).
        what: String,
    },
    /// An output folder holds one of the command's input files, which the files written
    /// into the folder could replace.
    #[error("refusing to write into {folder}: it holds the input {what} {input}, which the files written there could replace; give another output folder, or move the input out of it")]
    InputInOutputFolder {
        /// The output folder.
        folder: PathBuf,
        /// The input inside it.
        input: PathBuf,
        /// Which input it is.
        what: String,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
}

/// Formats a shape as `(a, b, c)`.
pub fn shape_string(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

fn open(path: &Path) -> Result<BufReader<File>, IoError> {
    open_regular(path).map(BufReader::new)
}

/// Opens `path` for reading when it is a regular file (after symbolic links): a
/// device (`/dev/zero`), a FIFO or a folder is refused before it is opened, since
/// reading one may never end (or, for a FIFO, opening it may never return).
pub fn open_regular(path: &Path) -> Result<File, IoError> {
    check_regular(path)?;
    File::open(path).map_err(|reason| IoError::Read {
        path: path.to_owned(),
        reason,
    })
}

/// Refuses `path` unless it is a regular file (after symbolic links); see
/// [`open_regular`].
pub fn check_regular(path: &Path) -> Result<(), IoError> {
    let metadata = std::fs::metadata(path).map_err(|reason| IoError::Read {
        path: path.to_owned(),
        reason,
    })?;
    if metadata.is_file() {
        return Ok(());
    }
    let kind = if metadata.is_dir() {
        "a folder"
    } else {
        "a device, FIFO or socket"
    };
    Err(IoError::Read {
        path: path.to_owned(),
        reason: std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("it is {kind}, not a regular file; smspace reads only regular files"),
        ),
    })
}

/// Most bytes of a text file smspace reads whole (an experiment, a configuration).
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// The text of the regular file `path`, refused above `max_bytes` before it is read.
pub fn read_text_bounded(path: &Path, max_bytes: u64) -> Result<String, IoError> {
    let file = open_regular(path)?;
    let read = |reason| IoError::Read {
        path: path.to_owned(),
        reason,
    };
    let size = file.metadata().map_err(read)?.len();
    let too_large = || {
        read(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("it holds more than {max_bytes} bytes, more than such a file may hold"),
        ))
    };
    if size > max_bytes {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(
        &mut std::io::Read::take(file, max_bytes.saturating_add(1)),
        &mut bytes,
    )
    .map_err(read)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large());
    }
    String::from_utf8(bytes).map_err(|e| {
        read(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("it is not UTF-8 text ({e})"),
        ))
    })
}

/// Reads a `.npy` array of any dimension whose elements are `A`, in standard (C)
/// layout whatever the file's order: NumPy writes `fortran_order: True` for an
/// F-contiguous array (`np.save(p, np.asfortranarray(a))`, a transposed view), and
/// every reader downstream may then take rows as contiguous slices.
fn read_any<A: ReadableElement + Clone>(path: &Path) -> Result<ArrayD<A>, IoError> {
    let mut reader = open(path)?;
    check_npy_size(path, reader.get_mut())?;
    std::io::Seek::rewind(reader.get_mut()).map_err(|reason| IoError::Read {
        path: path.to_owned(),
        reason,
    })?;
    let array = ArrayD::<A>::read_npy(reader).map_err(|error| match error {
        ReadNpyError::Io(reason) => IoError::Read {
            path: path.to_owned(),
            reason,
        },
        other => IoError::Npy {
            path: path.to_owned(),
            reason: other.to_string(),
        },
    })?;
    Ok(if array.is_standard_layout() {
        array
    } else {
        array.as_standard_layout().into_owned()
    })
}

/// Where the header text of a `.npy` file starts and ends (from its version and its
/// length field), when `head` holds those fields.
fn npy_header_range(head: &[u8]) -> Option<(usize, usize)> {
    let (length_bytes, start) = match head.get(6)? {
        1 => (2, 10),
        2 | 3 => (4, 12),
        _ => return None,
    };
    let mut length = 0usize;
    for (i, byte) in head.get(8..8 + length_bytes)?.iter().enumerate() {
        length |= (*byte as usize) << (8 * i);
    }
    Some((start, start + length))
}

/// The byte count a `.npy` header announces: `(offset of the data, bytes of data)`, from
/// the header's `descr` (the item size) and `shape`; `None` when the header does not
/// parse (the array reader then says what is wrong with it).
fn npy_layout(head: &[u8]) -> Option<(u64, u128)> {
    let (start, end) = npy_header_range(head)?;
    let header = std::str::from_utf8(head.get(start..end)?).ok()?;
    let descr = header.split("'descr'").nth(1)?;
    let descr = descr.split('\'').nth(1)?;
    let descr = descr.trim_start_matches(['<', '>', '|', '=']);
    // Numbers only (the item size is then the digits); other types are left to the
    // array reader, which refuses them by type.
    if !descr.starts_with(['f', 'i', 'u', 'b']) {
        return None;
    }
    let item: u128 = descr.get(1..)?.parse().ok()?;
    let shape = header.split("'shape'").nth(1)?;
    let shape = shape.split('(').nth(1)?.split(')').next()?;
    let mut count: u128 = 1;
    for extent in shape.split(',').map(str::trim).filter(|e| !e.is_empty()) {
        // Past u128 no file can hold it: saturate, and the size check refuses it.
        count = count.saturating_mul(extent.parse::<u64>().ok()? as u128);
    }
    Some((end as u64, count.saturating_mul(item)))
}

/// Refuses a `.npy` file whose header announces more (or fewer) bytes than the file
/// holds, before any array is allocated from that header: a damaged or hostile header
/// never makes the reader allocate more than the file's own size.
fn check_npy_size(path: &Path, file: &mut File) -> Result<(), IoError> {
    let read_error = |reason| IoError::Read {
        path: path.to_owned(),
        reason,
    };
    let size = file.metadata().map_err(read_error)?.len();
    let incomplete = |reason: String| IoError::Incomplete {
        path: path.to_owned(),
        reason,
    };
    if size == 0 {
        return Err(incomplete("the file is empty".into()));
    }
    let mut head = Vec::with_capacity(4096);
    std::io::Read::read_to_end(&mut std::io::Read::take(&mut *file, 65_536), &mut head)
        .map_err(read_error)?;
    if !head.starts_with(b"\x93NUMPY") {
        return Err(IoError::Npy {
            path: path.to_owned(),
            reason: "it does not start with the .npy magic bytes \\x93NUMPY".into(),
        });
    }
    if head.len() < 10 {
        return Err(incomplete(format!(
            "{size} bytes, shorter than a .npy header"
        )));
    }
    if let Some((_, end)) = npy_header_range(&head) {
        if end as u64 > size {
            return Err(incomplete(format!(
                "its header runs to byte {end} but the file has {size} bytes"
            )));
        }
    }
    let Some((start, data)) = npy_layout(&head) else {
        // A header that does not parse: the array reader names the problem.
        return Ok(());
    };
    let found = (size - start) as u128;
    if found != data {
        return Err(incomplete(format!(
            "its header announces {data} bytes of data, the file holds {found} after the header"
        )));
    }
    Ok(())
}

/// The shape a `.npy` file's header announces, read without the data (so that the
/// memory a computation on it needs can be estimated before anything is allocated);
/// `None` when the header does not parse (the array reader then says why).
pub fn npy_shape(path: &Path) -> Result<Option<Vec<usize>>, IoError> {
    let mut file = open_regular(path)?;
    let mut head = Vec::with_capacity(4096);
    std::io::Read::read_to_end(&mut std::io::Read::take(&mut file, 65_536), &mut head).map_err(
        |reason| IoError::Read {
            path: path.to_owned(),
            reason,
        },
    )?;
    let Some((start, end)) = npy_header_range(&head) else {
        return Ok(None);
    };
    let Some(header) = head
        .get(start..end)
        .and_then(|h| std::str::from_utf8(h).ok())
    else {
        return Ok(None);
    };
    let shape = header
        .split("'shape'")
        .nth(1)
        .and_then(|s| s.split('(').nth(1))
        .and_then(|s| s.split(')').next());
    Ok(shape.and_then(|shape| {
        shape
            .split(',')
            .map(str::trim)
            .filter(|e| !e.is_empty())
            .map(|e| e.parse::<usize>().ok())
            .collect()
    }))
}

/// Reads a `float64` `.npy` array of any dimension, checking that every entry is finite.
pub fn read_f64(path: &Path) -> Result<ArrayD<f64>, IoError> {
    let array = read_any::<f64>(path)?;
    check_finite(path, &array)?;
    Ok(array)
}

/// Reads an `int64` `.npy` array of any dimension (probe labels, kept rows).
pub fn read_i64(path: &Path) -> Result<ArrayD<i64>, IoError> {
    read_any(path)
}

/// Returns an error naming the first non-finite entry of `array`.
pub fn check_finite<S: Data<Elem = f64>, D: Dimension>(
    path: &Path,
    array: &ArrayBase<S, D>,
) -> Result<(), IoError> {
    match first_non_finite(array) {
        Some((index, value)) => Err(IoError::NonFinite {
            path: path.to_owned(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Reads a 2-D `float64` array; `columns`, when given, is the required second extent.
///
/// `expected` describes the shape for the error message, e.g. `"(M, 4)"`.
pub fn read_matrix(
    path: &Path,
    columns: Option<usize>,
    expected: &str,
) -> Result<Array2<f64>, IoError> {
    let array = read_f64(path)?;
    let shape_error = |array: &ArrayD<f64>| IoError::Shape {
        path: path.to_owned(),
        found: shape_string(array.shape()),
        expected: expected.to_owned(),
    };
    if array.ndim() != 2 || columns.is_some_and(|c| array.shape()[1] != c) {
        return Err(shape_error(&array));
    }
    array
        .into_dimensionality::<Ix2>()
        .map_err(|_| IoError::Shape {
            path: path.to_owned(),
            found: "?".into(),
            expected: expected.to_owned(),
        })
}

/// Reads a 3-D `float64` array such as kernel sets `(M, P, N)`.
pub fn read_cube(path: &Path, expected: &str) -> Result<Array3<f64>, IoError> {
    let array = read_f64(path)?;
    if array.ndim() != 3 {
        return Err(IoError::Shape {
            path: path.to_owned(),
            found: shape_string(array.shape()),
            expected: expected.to_owned(),
        });
    }
    array
        .into_dimensionality::<Ix3>()
        .map_err(|_| IoError::Shape {
            path: path.to_owned(),
            found: "?".into(),
            expected: expected.to_owned(),
        })
}

/// The file next to `path` that shares its stem: `sibling("run/sets.npy", "kept.npy")`
/// is `run/sets.kept.npy`. Companion files (reports, records) are named this way.
///
/// ```
/// use std::path::Path;
/// assert_eq!(
///     smspace::io::sibling(Path::new("run/sets.npy"), "kept.npy"),
///     Path::new("run/sets.kept.npy")
/// );
/// ```
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}.{suffix}"))
}

/// The folder that holds `path` (`.` for a bare file name).
pub fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    }
}

/// An input file of a command, named by what gives it (`--motors`, `[data] sensors`),
/// that no output may replace ([`check_outputs_spare_inputs`]).
#[derive(Debug, Clone, Copy)]
pub struct Input<'a> {
    /// What gives the file: an option or a key, for the message.
    pub what: &'a str,
    /// The file.
    pub path: &'a Path,
}

impl<'a> Input<'a> {
    /// The input `path`, given by `what`.
    pub fn new(what: &'a str, path: &'a Path) -> Self {
        Self { what, path }
    }
}

/// `path` made absolute and resolved as far as it exists: its longest existing
/// ancestor canonicalised (links and `..` resolved), the rest appended as written.
fn resolved(path: &Path) -> PathBuf {
    if let Ok(full) = std::fs::canonicalize(path) {
        return full;
    }
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
    let mut rest = Vec::new();
    let mut head = absolute.as_path();
    loop {
        if let Ok(full) = std::fs::canonicalize(head) {
            return rest.iter().rev().fold(full, |p, part| p.join(part));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_owned());
                head = parent;
            }
            _ => return absolute,
        }
    }
}

/// Whether `a` and `b` name the same file: the same device and inode when both exist
/// (hard links, symbolic links, `..` and `.` alike), else the same resolved path.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return (x.dev(), x.ino()) == (y.dev(), y.ino());
        }
    }
    resolved(a) == resolved(b)
}

/// Refuses any of `outputs` that names one of `inputs` (by path, link or inode; see
/// [`same_file`]): a command must never write over the files it reads. Every command
/// and the pipeline call this before their work starts, and again on the files they
/// stage.
///
/// ```
/// # let dir = tempfile::tempdir().unwrap();
/// use smspace::io::{check_outputs_spare_inputs, Input};
/// let motors = dir.path().join("motors.npy");
/// std::fs::write(&motors, b"").unwrap();
/// let same = dir.path().join(".").join("motors.npy");
/// let inputs = [Input::new("--motors", &motors)];
/// assert!(check_outputs_spare_inputs([same.as_path()], &inputs).is_err());
/// assert!(check_outputs_spare_inputs([dir.path().join("sets.npy").as_path()], &inputs).is_ok());
/// ```
pub fn check_outputs_spare_inputs<'p>(
    outputs: impl IntoIterator<Item = &'p Path>,
    inputs: &[Input<'_>],
) -> Result<(), IoError> {
    for output in outputs {
        if let Some(input) = inputs.iter().find(|i| same_file(output, i.path)) {
            return Err(IoError::OutputIsInput {
                output: output.to_owned(),
                input: input.path.to_owned(),
                what: input.what.to_owned(),
            });
        }
    }
    Ok(())
}

/// Refuses `path` as an output when its folder does not exist or is not a folder:
/// checked before the work that makes the output, so that a long computation does not
/// end at a folder that cannot take its result.
pub fn check_output_folder(path: &Path) -> Result<(), IoError> {
    let folder = folder_of(path);
    if folder.is_dir() {
        return Ok(());
    }
    let reason = if folder.exists() {
        format!("{} is not a folder", folder.display())
    } else {
        format!(
            "its folder {} does not exist; create it first (mkdir -p {})",
            folder.display(),
            folder.display()
        )
    };
    Err(IoError::Write {
        path: path.to_owned(),
        reason: std::io::Error::new(std::io::ErrorKind::NotFound, reason),
    })
}

/// Refuses an output folder that holds one of `inputs`, at any depth (a run folder,
/// whose files are all smspace's to replace): by resolved path, so that links and `..`
/// cannot hide an input inside it.
pub fn check_folder_spares_inputs(folder: &Path, inputs: &[Input<'_>]) -> Result<(), IoError> {
    let folder_resolved = resolved(folder);
    for input in inputs {
        let parent = resolved(&folder_of(input.path));
        if parent.starts_with(&folder_resolved) {
            return Err(IoError::InputInOutputFolder {
                folder: folder.to_owned(),
                input: input.path.to_owned(),
                what: input.what.to_owned(),
            });
        }
    }
    Ok(())
}

/// Start of the name of every temporary file smspace writes (`.smspace-XXXXXX.part`).
pub const TEMP_PREFIX: &str = ".smspace-";

/// End of the name of every temporary file smspace writes.
pub const TEMP_SUFFIX: &str = ".part";

/// The writer that `fill` closures of [`write_atomic`] and [`Outputs::file`] write into:
/// buffered, in front of the temporary file.
pub type OutputWriter<'a> = BufWriter<Hashing<&'a mut File>>;

/// A writer that passes every byte on to `inner` and hashes (BLAKE3) exactly the bytes
/// `inner` accepted: the hash of a file is taken while it is written, never by reading
/// it back (when something else may have replaced it).
#[derive(Debug)]
pub struct Hashing<W> {
    inner: W,
    hasher: blake3::Hasher,
}

impl<W: Write> Write for Hashing<W> {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let written = self.inner.write(bytes)?;
        self.hasher.update(&bytes[..written]);
        Ok(written)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// A file written in full to its temporary name, with the BLAKE3 hash of its bytes.
#[derive(Debug)]
struct Staged {
    temp: tempfile::NamedTempFile,
    path: PathBuf,
    blake3: String,
}

/// Writes `fill`'s bytes into a new temporary file (`.smspace-*.part`) in the folder of
/// `path`, flushed and synced, ready to be renamed over `path`; hashes them on the way.
fn stage<F>(path: &Path, fill: F) -> Result<Staged, IoError>
where
    F: FnOnce(&mut OutputWriter<'_>) -> std::io::Result<()>,
{
    let write_error = |reason| IoError::Write {
        path: path.to_owned(),
        reason,
    };
    let folder = folder_of(path);
    let mut builder = tempfile::Builder::new();
    builder.prefix(TEMP_PREFIX).suffix(TEMP_SUFFIX);
    #[cfg(unix)]
    {
        // Outputs are ordinary files (rw-r--r--), not private temporaries.
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut temp = builder.tempfile_in(&folder).map_err(write_error)?;
    let hasher = {
        let mut writer = BufWriter::new(Hashing {
            inner: temp.as_file_mut(),
            hasher: blake3::Hasher::new(),
        });
        fill(&mut writer).map_err(write_error)?;
        writer.flush().map_err(write_error)?;
        let hashing = writer
            .into_inner()
            .map_err(|e| write_error(e.into_error()))?;
        hashing.hasher
    };
    temp.as_file().sync_all().map_err(write_error)?;
    Ok(Staged {
        temp,
        path: path.to_owned(),
        blake3: hasher.finalize().to_hex().to_string(),
    })
}

/// Writes `path` atomically: `fill` writes into a temporary file in the same folder,
/// which is renamed over `path` only once it is complete and flushed.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<(), IoError>
where
    F: FnOnce(&mut OutputWriter<'_>) -> std::io::Result<()>,
{
    persist(stage(path, fill)?)
}

/// Renames a staged file over its destination.
fn persist(staged: Staged) -> Result<(), IoError> {
    let Staged { temp, path, .. } = staged;
    temp.persist(&path).map_err(|e| IoError::Write {
        path,
        reason: e.error,
    })?;
    Ok(())
}

/// Writes `array` as `.npy` bytes.
fn fill_npy<A, S, D>(writer: &mut OutputWriter<'_>, array: &ArrayBase<S, D>) -> std::io::Result<()>
where
    A: WritableElement,
    S: Data<Elem = A>,
    D: Dimension,
{
    array
        .write_npy(writer)
        .map_err(|e| std::io::Error::other(e.to_string()))
}

/// Writes `value` as pretty-printed JSON and a final newline.
fn fill_json<T: Serialize + ?Sized>(
    writer: &mut OutputWriter<'_>,
    value: &T,
) -> std::io::Result<()> {
    serde_json::to_writer_pretty(&mut *writer, value).map_err(std::io::Error::other)?;
    writer.write_all(b"\n")
}

/// The files of one command or stage, written together: every file is first written
/// in full to its own temporary file, and only then, once every destination has been
/// checked to take a file (its folder exists, its name is valid), are they all renamed
/// into place, in the order they were staged. A failure before that point (a
/// non-finite array, a full disk, a name too long) leaves every earlier output as it
/// was.
///
/// Each file's BLAKE3 hash is taken from the bytes as they are written
/// ([`staged`](Outputs::staged)), so a record of what was written (the run's manifest)
/// never depends on reading the files back.
///
/// ```
/// # let dir = tempfile::tempdir().unwrap();
/// let mut outputs = smspace::io::Outputs::new();
/// outputs.npy(&dir.path().join("a.npy"), &ndarray::array![1.0, 2.0])?;
/// outputs.json(&dir.path().join("a.json"), &serde_json::json!({"rows": 2}))?;
/// assert_eq!(outputs.staged().count(), 2);
/// outputs.commit()?;
/// assert!(dir.path().join("a.npy").is_file() && dir.path().join("a.json").is_file());
/// # Ok::<(), smspace::io::IoError>(())
/// ```
#[derive(Debug, Default)]
pub struct Outputs {
    staged: Vec<Staged>,
    /// Files no staged path may name (see [`Outputs::sparing`]).
    inputs: Vec<(String, PathBuf)>,
}

impl Outputs {
    /// No file yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// No file yet; every file staged later is first checked not to name one of
    /// `inputs` ([`check_outputs_spare_inputs`]), before a byte of it is written.
    pub fn sparing(inputs: &[Input<'_>]) -> Self {
        Self {
            staged: Vec::new(),
            inputs: inputs
                .iter()
                .map(|i| (i.what.to_owned(), i.path.to_owned()))
                .collect(),
        }
    }

    /// Stages `path`, written by `fill`.
    pub fn file<F>(&mut self, path: &Path, fill: F) -> Result<(), IoError>
    where
        F: FnOnce(&mut OutputWriter<'_>) -> std::io::Result<()>,
    {
        let inputs: Vec<Input<'_>> = self
            .inputs
            .iter()
            .map(|(what, path)| Input::new(what, path))
            .collect();
        check_outputs_spare_inputs([path], &inputs)?;
        self.staged.push(stage(path, fill)?);
        Ok(())
    }

    /// Stages `bytes` as the content of `path`.
    pub fn bytes(&mut self, path: &Path, bytes: &[u8]) -> Result<(), IoError> {
        self.file(path, |writer| writer.write_all(bytes))
    }

    /// Stages an array as `.npy`; refuses an array with NaN or an infinity (see
    /// [`write_npy`]).
    pub fn npy<A, S, D>(&mut self, path: &Path, array: &ArrayBase<S, D>) -> Result<(), IoError>
    where
        A: NpyElement,
        S: Data<Elem = A>,
        D: Dimension,
    {
        check_writable_values(path, array)?;
        self.file(path, |writer| fill_npy(writer, array))
    }

    /// Stages a value as pretty-printed JSON.
    pub fn json<T: Serialize + ?Sized>(&mut self, path: &Path, value: &T) -> Result<(), IoError> {
        self.file(path, |writer| fill_json(writer, value))
    }

    /// The files staged so far, in order, each with the hex BLAKE3 hash of the bytes
    /// written into it.
    pub fn staged(&self) -> impl Iterator<Item = (&Path, &str)> {
        self.staged
            .iter()
            .map(|s| (s.path.as_path(), s.blake3.as_str()))
    }

    /// Checks every destination, then renames every staged file into place; returns
    /// the destinations in the order they were staged.
    pub fn commit(self) -> Result<Vec<PathBuf>, IoError> {
        for staged in &self.staged {
            check_destination(&staged.path)?;
        }
        let mut written = Vec::with_capacity(self.staged.len());
        for staged in self.staged {
            written.push(staged.path.clone());
            persist(staged)?;
        }
        Ok(written)
    }
}

/// Whether a file can be renamed to `path`: an existing entry that is not a folder can
/// (a file, or a link, a FIFO or a device node, which the rename replaces without
/// opening it); else a new file of that name is made and removed again (which catches a
/// name that is too long or a folder that refuses it), leaving nothing behind.
fn check_destination(path: &Path) -> Result<(), IoError> {
    let entry = std::fs::symlink_metadata(path);
    if entry.as_ref().is_ok_and(|m| !m.is_dir()) {
        return Ok(());
    }
    if entry.is_ok_and(|m| m.is_dir()) {
        return Err(IoError::Write {
            path: path.to_owned(),
            reason: std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "a folder of that name is in the way",
            ),
        });
    }
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .and_then(|_| std::fs::remove_file(path))
        .map_err(|reason| IoError::Write {
            path: path.to_owned(),
            reason,
        })
}

/// An element type smspace writes to `.npy`, and whether a value of it is finite.
pub trait NpyElement: WritableElement {
    /// The value as `f64` when it is NaN or infinite, else `None`.
    fn non_finite(&self) -> Option<f64> {
        None
    }
}

impl NpyElement for f64 {
    fn non_finite(&self) -> Option<f64> {
        (!self.is_finite()).then_some(*self)
    }
}

impl NpyElement for f32 {
    fn non_finite(&self) -> Option<f64> {
        (!self.is_finite()).then_some(f64::from(*self))
    }
}

impl NpyElement for i64 {}
impl NpyElement for i32 {}
impl NpyElement for u8 {}
impl NpyElement for bool {}

/// Writes an array as `.npy` (little-endian, C order), atomically; refuses
/// ([`IoError::NonFiniteOutput`], nothing written) an array that holds NaN or an
/// infinity.
pub fn write_npy<A, S, D>(path: &Path, array: &ArrayBase<S, D>) -> Result<(), IoError>
where
    A: NpyElement,
    S: Data<Elem = A>,
    D: Dimension,
{
    check_writable_values(path, array)?;
    write_atomic(path, |writer| fill_npy(writer, array))
}

/// The first entry of `array` that is NaN or infinite, as `(index, value)` with the
/// index formatted like a shape.
fn first_non_finite<A, S, D>(array: &ArrayBase<S, D>) -> Option<(String, f64)>
where
    A: NpyElement,
    S: Data<Elem = A>,
    D: Dimension,
{
    let view = array.view().into_dyn();
    view.indexed_iter().find_map(|(index, v)| {
        v.non_finite()
            .map(|value| (shape_string(index.slice()), value))
    })
}

/// Refuses ([`IoError::NonFiniteOutput`]) an array that holds NaN or an infinity.
fn check_writable_values<A, S, D>(path: &Path, array: &ArrayBase<S, D>) -> Result<(), IoError>
where
    A: NpyElement,
    S: Data<Elem = A>,
    D: Dimension,
{
    match first_non_finite(array) {
        Some((index, value)) => Err(IoError::NonFiniteOutput {
            path: path.to_owned(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Writes a value as pretty-printed JSON, atomically.
pub fn write_json<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), IoError> {
    write_atomic(path, |writer| fill_json(writer, value))
}

/// Reads a JSON document; `what` names it in error messages (e.g. "environment").
pub fn read_json<T: DeserializeOwned>(path: &Path, what: &'static str) -> Result<T, IoError> {
    let reader = open(path)?;
    serde_json::from_reader(reader).map_err(|reason| IoError::Json {
        path: path.to_owned(),
        what,
        reason,
    })
}

/// Formats a byte count as `12.3 GiB`.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// A `.npy` file with `header` (padded as NumPy does) and `body`.
    fn npy_bytes(header: &str, body: &[u8]) -> Vec<u8> {
        let mut header = header.to_owned();
        while !(10 + header.len() + 1).is_multiple_of(64) {
            header.push(' ');
        }
        header.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(body);
        bytes
    }

    #[test]
    fn a_header_larger_than_its_file_is_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bomb.npy");
        for shape in ["(1000000000, 1000000000)", "(100000, 100000)", "(3, 2)"] {
            let header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
            std::fs::write(&path, npy_bytes(&header, &[0u8; 40])).unwrap();
            let err = read_f64(&path).unwrap_err();
            assert!(matches!(err, IoError::Incomplete { .. }), "{err}");
            assert!(err.to_string().contains("after the header"), "{err}");
        }
        // A shape whose byte count overflows is refused too.
        let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551615, 18446744073709551615, 18446744073709551615), }";
        std::fs::write(&path, npy_bytes(header, &[])).unwrap();
        let err = read_f64(&path).unwrap_err();
        assert!(matches!(err, IoError::Incomplete { .. }), "{err}");
        // Empty, truncated inside the header, not a .npy file at all.
        std::fs::write(&path, b"").unwrap();
        assert!(read_f64(&path)
            .unwrap_err()
            .to_string()
            .contains("is empty"));
        std::fs::write(&path, b"\x93NUMPY\x01").unwrap();
        let err = read_f64(&path).unwrap_err().to_string();
        assert!(err.contains("shorter than a .npy header"), "{err}");
        let whole = npy_bytes(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }",
            &[0; 16],
        );
        std::fs::write(&path, &whole[..40]).unwrap();
        let err = read_f64(&path).unwrap_err().to_string();
        assert!(err.contains("not a complete .npy file"), "{err}");
        std::fs::write(&path, b"x,y\n1,2\n3,4\n").unwrap();
        let err = read_f64(&path).unwrap_err().to_string();
        assert!(err.contains("magic"), "{err}");
        // The exact size reads.
        std::fs::write(&path, &whole).unwrap();
        assert_eq!(read_f64(&path).unwrap().shape(), &[2]);
    }

    #[test]
    fn outputs_appear_together_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.npy");
        write_npy(&a, &array![1.0]).unwrap();
        // The second destination's name is too long for the file system: the first
        // file is not replaced either.
        let long = dir.path().join(format!("{}.json", "x".repeat(300)));
        let mut outputs = Outputs::new();
        outputs.npy(&a, &array![2.0, 3.0]).unwrap();
        outputs.json(&long, &[1, 2]).unwrap();
        assert!(matches!(outputs.commit(), Err(IoError::Write { .. })));
        assert_eq!(read_f64(&a).unwrap().shape(), &[1]);
        // No temporary file stays behind.
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.npy"]);
        // A non-finite array fails while staging, before anything is renamed.
        let mut outputs = Outputs::new();
        outputs.npy(&a, &array![5.0]).unwrap();
        assert!(outputs
            .npy(&dir.path().join("b.npy"), &array![f64::NAN])
            .is_err());
        drop(outputs);
        assert_eq!(read_f64(&a).unwrap().shape(), &[1]);
    }

    #[test]
    fn hashes_are_of_the_bytes_written_never_of_a_re_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.bin");
        let ours = b"what this writer wrote".repeat(1000);
        let expected = blake3::hash(&ours).to_hex().to_string();
        // Another program keeps replacing the file while it is written and renamed.
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let intruder = {
            let (path, stop) = (path.clone(), stop.clone());
            std::thread::spawn(move || {
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    let _ = std::fs::write(&path, b"someone else's bytes");
                }
            })
        };
        for _ in 0..200 {
            let mut outputs = Outputs::new();
            outputs.bytes(&path, &ours).unwrap();
            let staged: Vec<(PathBuf, String)> = outputs
                .staged()
                .map(|(p, h)| (p.to_owned(), h.to_owned()))
                .collect();
            outputs.commit().unwrap();
            assert_eq!(staged, [(path.clone(), expected.clone())]);
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        intruder.join().unwrap();
        // Alone, the file holds exactly the bytes hashed.
        let mut outputs = Outputs::new();
        outputs.npy(&path, &array![1.0, 2.0]).unwrap();
        let hash = outputs.staged().next().unwrap().1.to_owned();
        outputs.commit().unwrap();
        assert_eq!(
            blake3::hash(&std::fs::read(&path).unwrap())
                .to_hex()
                .to_string(),
            hash
        );
    }

    #[test]
    fn non_finite_arrays_are_never_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("y.npy");
        write_npy(&path, &array![[1.0, 2.0]]).unwrap();
        let err = write_npy(&path, &array![[1.0, 2.0], [f64::INFINITY, 0.0]]).unwrap_err();
        assert!(matches!(err, IoError::NonFiniteOutput { .. }), "{err}");
        assert!(err.to_string().contains("(1, 0)"), "{err}");
        // The earlier file is untouched.
        assert_eq!(
            read_matrix(&path, Some(2), "(M, 2)").unwrap(),
            array![[1.0, 2.0]]
        );
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig {
            cases: 256,
            rng_seed: proptest::test_runner::RngSeed::Fixed(19),
            ..Default::default()
        })]

        /// Arbitrary bytes, with or without a valid header in front: an error or an
        /// array, never a panic or an allocation beyond the file.
        #[test]
        fn arbitrary_bytes_never_crash_the_reader(
            body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
            shape in proptest::collection::vec(0u64..u64::MAX, 0..4),
            framed in proptest::prelude::any::<bool>(),
        ) {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("any.npy");
            let bytes = if framed {
                let shape: Vec<String> = shape.iter().map(|n| format!("{n}, ")).collect();
                let header = format!(
                    "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}), }}",
                    shape.concat().trim_end()
                );
                npy_bytes(&header, &body)
            } else {
                body
            };
            std::fs::write(&path, bytes).unwrap();
            let _ = read_f64(&path);
            let _ = read_i64(&path);
        }
    }

    #[test]
    fn round_trip_and_shape_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        let a = array![[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]];
        write_npy(&path, &a).unwrap();
        assert_eq!(read_matrix(&path, Some(2), "(M, 2)").unwrap(), a);
        let err = read_matrix(&path, Some(4), "(M, 4)").unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("{} has shape (3, 2), expected (M, 4)", path.display())
        );
        assert!(matches!(
            read_cube(&path, "(M, P, N)"),
            Err(IoError::Shape { .. })
        ));
    }

    /// A `.npy` file as NumPy writes a Fortran-ordered array (`np.save(p,
    /// np.asfortranarray(a))`): the flag in the header, the first index fastest.
    fn fortran_npy<D: Dimension>(a: &ndarray::Array<f64, D>) -> Vec<u8> {
        let shape: Vec<String> = a.shape().iter().map(|n| format!("{n}, ")).collect();
        let mut header = format!(
            "{{'descr': '<f8', 'fortran_order': True, 'shape': ({}), }}",
            shape.concat().trim_end()
        );
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        for x in a.view().reversed_axes().iter() {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        bytes
    }

    #[test]
    fn fortran_order_files_read_in_standard_layout() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.npy");
        let a = array![[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]];
        std::fs::write(&path, fortran_npy(&a)).unwrap();
        let back = read_matrix(&path, Some(2), "(M, 2)").unwrap();
        assert!(back.is_standard_layout());
        assert_eq!(back, a);
        assert_eq!(back.row(2).as_slice().unwrap(), &[5.0, 6.0]);
        let cube =
            ndarray::Array3::from_shape_fn((2, 3, 4), |(i, j, k)| (i * 12 + j * 4 + k) as f64);
        std::fs::write(&path, fortran_npy(&cube)).unwrap();
        let back = read_cube(&path, "(M, P, N)").unwrap();
        assert!(back.is_standard_layout());
        assert_eq!(back, cube);
    }

    #[test]
    fn nan_is_reported_with_its_index() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nan.npy");
        // smspace never writes one (see `non_finite_arrays_are_never_written`): NumPy can.
        ndarray_npy::write_npy(&path, &array![[1.0, f64::NAN]]).unwrap();
        let err = read_matrix(&path, None, "(M, N)").unwrap_err();
        assert!(err.to_string().contains("(0, 1)"), "{err}");
    }

    #[test]
    fn wrong_dtype_names_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("int.npy");
        write_npy(&path, &array![[1_i64, 2]]).unwrap();
        let err = read_matrix(&path, None, "(M, N)").unwrap_err();
        assert!(err.to_string().contains("astype(numpy.float64)"), "{err}");
    }

    #[test]
    fn an_output_naming_an_input_is_refused_by_path_link_and_inode() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log");
        std::fs::create_dir(&log).unwrap();
        let motors = log.join("motors.npy");
        std::fs::write(&motors, b"motors").unwrap();
        let inputs = [Input::new("--motors", &motors)];
        let dotted = dir.path().join("log/../log/./motors.npy");
        let hard = dir.path().join("hard.npy");
        std::fs::hard_link(&motors, &hard).unwrap();
        let soft = dir.path().join("soft.npy");
        #[cfg(unix)]
        std::os::unix::fs::symlink(&motors, &soft).unwrap();
        for output in [&motors, &dotted, &hard, &soft] {
            let err = check_outputs_spare_inputs([output.as_path()], &inputs)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("--motors") && err.contains("motors.npy") && err.contains("elsewhere"),
                "{err}"
            );
        }
        // Staging through `Outputs::sparing` refuses it before writing anything.
        let mut outputs = Outputs::sparing(&inputs);
        assert!(outputs.npy(&dotted, &ndarray::array![1.0]).is_err());
        assert_eq!(std::fs::read(&motors).unwrap(), b"motors");
        // A new file beside it, and a folder that does not hold it, are fine.
        check_outputs_spare_inputs([log.join("sets.npy").as_path()], &inputs).unwrap();
        check_folder_spares_inputs(&dir.path().join("run"), &inputs).unwrap();
        let err = check_folder_spares_inputs(dir.path(), &inputs)
            .unwrap_err()
            .to_string();
        assert!(err.contains("holds the input --motors"), "{err}");
    }

    #[test]
    fn atomic_write_leaves_no_temporary_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.json");
        write_json(&path, &vec![1, 2, 3]).unwrap();
        write_json(&path, &vec![4]).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
        let back: Vec<i32> = read_json(&path, "test").unwrap();
        assert_eq!(back, vec![4]);
    }
}
