//! One writer per run folder: an advisory lock on `DIR/.smspace.lock`, held from before
//! the first file of the folder is touched until the run returns.
//!
//! Two `smspace run` into one folder would otherwise interleave their stage files and
//! manifests, so that a manifest could record another run's output under its own key
//! and every later run would reuse it. The lock is the operating system's (`flock` on
//! Unix, `LockFileEx` on Windows, through [`std::fs::File::lock`]), so it is released
//! when the process ends, however it ends: a killed run never leaves a stale lock.
//!
//! A folder whose lock file cannot be opened for writing (a read-only folder or file
//! system) is opened for reading only ([`Access::ReadOnly`]): the run takes a *shared*
//! lock on the lock file when there is one (no writer can then hold the folder, and
//! other readers may), or none when the folder has no lock file (nothing can create
//! one, so no smspace run can write there either). Such a run writes nothing: it can
//! only reuse a finished run whose configuration is unchanged.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// A run folder that cannot be taken.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LockError {
    /// Another process is writing the run folder (and [`BusyFolder::Refuse`]).
    #[error("another smspace run is writing {dir} (it holds {lock}); wait for it to end, pass --wait to queue behind it, or choose another --out folder")]
    Busy {
        /// The run folder.
        dir: PathBuf,
        /// Its lock file.
        lock: PathBuf,
    },
    /// The lock file of the run folder cannot be opened or locked.
    #[error("cannot lock the run folder through {path}: {reason}")]
    Lock {
        /// The lock file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
}

/// Name of the lock file inside a run folder.
pub const LOCK_FILE: &str = ".smspace.lock";

/// What a run does when another process is writing its folder.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BusyFolder {
    /// Fail at once with [`LockError::Busy`] (the default).
    #[default]
    Refuse,
    /// Wait until the other run ends, then run.
    Wait,
}

/// What a run may do in its folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// The run holds the exclusive lock: it may write.
    Write,
    /// The folder cannot be written: the run holds a shared lock (or none, when the
    /// folder has no lock file) and writes nothing.
    ReadOnly,
}

/// The held lock; dropping it releases the folder.
#[derive(Debug)]
pub(super) struct FolderLock {
    _file: Option<File>,
    access: Access,
}

impl FolderLock {
    /// Takes the lock of `dir` (which exists), waiting or refusing as `busy` says;
    /// `waiting` is called once before a wait. Exclusive when the lock file can be
    /// opened for writing, shared (or none) when the folder is read-only.
    pub(super) fn acquire(
        dir: &Path,
        busy: BusyFolder,
        waiting: impl FnOnce(&Path),
    ) -> Result<Self, LockError> {
        let path = lock_path(dir);
        let lock_error = |reason| LockError::Lock {
            path: path.clone(),
            reason,
        };
        let writable = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path);
        let (file, access) = match writable {
            Ok(file) => (file, Access::Write),
            Err(reason) if is_read_only(&reason) => match File::open(&path) {
                Ok(file) => (file, Access::ReadOnly),
                Err(missing) if missing.kind() == std::io::ErrorKind::NotFound => {
                    return Ok(Self {
                        _file: None,
                        access: Access::ReadOnly,
                    })
                }
                Err(other) => return Err(lock_error(other)),
            },
            Err(reason) => return Err(lock_error(reason)),
        };
        let tried = match access {
            Access::Write => file.try_lock(),
            Access::ReadOnly => file.try_lock_shared(),
        };
        match tried {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => match busy {
                BusyFolder::Refuse => {
                    return Err(LockError::Busy {
                        dir: dir.to_owned(),
                        lock: path,
                    })
                }
                BusyFolder::Wait => {
                    waiting(&path);
                    match access {
                        Access::Write => file.lock(),
                        Access::ReadOnly => file.lock_shared(),
                    }
                    .map_err(lock_error)?;
                }
            },
            Err(TryLockError::Error(reason)) => return Err(lock_error(reason)),
        }
        Ok(Self {
            _file: Some(file),
            access,
        })
    }

    /// Whether the run may write its folder.
    pub(super) fn access(&self) -> Access {
        self.access
    }
}

/// Whether opening a file for writing failed because the folder or file system is
/// read-only (rather than missing, say).
pub(super) fn is_read_only(error: &std::io::Error) -> bool {
    matches!(
        error.kind(),
        std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::ReadOnlyFilesystem
    )
}

/// Folder levels below a run folder searched for stale temporary files (`figures/`,
/// `assets/`, and anything a stage writes below them).
const STALE_PART_DEPTH: usize = 3;

/// Removes the temporary files (`.smspace-*.part`, see [`smspace::io::write_atomic`]) that
/// an interrupted writer left in `dir` and every folder below it (`figures/`,
/// `assets/`, …, [`STALE_PART_DEPTH`] levels deep; symbolic links are not followed).
/// Only called while the folder's lock is held, so no other run is writing them;
/// returns how many were removed.
pub(super) fn remove_stale_parts(dir: &Path) -> usize {
    let mut removed = 0;
    let mut folders = vec![(dir.to_owned(), 0)];
    while let Some((folder, depth)) = folders.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let Ok(kind) = entry.file_type() else {
                continue;
            };
            if kind.is_dir() && depth < STALE_PART_DEPTH {
                folders.push((entry.path(), depth + 1));
                continue;
            }
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with(smspace::io::TEMP_PREFIX)
                && name.ends_with(smspace::io::TEMP_SUFFIX)
                && kind.is_file()
                && std::fs::remove_file(entry.path()).is_ok()
            {
                removed += 1;
            }
        }
    }
    removed
}

/// The lock file of a run folder.
pub fn lock_path(dir: &Path) -> PathBuf {
    dir.join(LOCK_FILE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_until_the_first_is_done() {
        let dir = tempfile::tempdir().unwrap();
        let first = FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap();
        let second = FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {});
        match second {
            Err(LockError::Busy { dir: busy, lock }) => {
                assert_eq!(busy, dir.path());
                assert_eq!(lock, lock_path(dir.path()));
            }
            other => panic!("expected Busy, got {other:?}"),
        }
        drop(first);
        FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap();
    }

    #[test]
    fn readers_share_the_lock_and_keep_writers_out() {
        let dir = tempfile::tempdir().unwrap();
        drop(FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap());
        // What `acquire` takes when the lock file cannot be opened for writing.
        let shared = || {
            let file = File::open(lock_path(dir.path())).unwrap();
            file.try_lock_shared().map(|()| file)
        };
        let first = shared().unwrap();
        let second = shared().expect("readers share the folder");
        let writer = FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {});
        assert!(matches!(writer, Err(LockError::Busy { .. })));
        drop((first, second));
        let writer = FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap();
        assert_eq!(writer.access(), Access::Write);
        assert!(shared().is_err(), "no reader while a writer holds it");
        let read_only = std::io::Error::from(std::io::ErrorKind::ReadOnlyFilesystem);
        assert!(is_read_only(&read_only));
        assert!(!is_read_only(&std::io::Error::from(
            std::io::ErrorKind::NotFound
        )));
    }

    #[test]
    fn stale_temporary_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("figures")).unwrap();
        std::fs::create_dir(dir.path().join("assets")).unwrap();
        for name in [
            ".smspace-a1.part",
            "figures/.smspace-b2.part",
            "assets/.smspace-c3.part",
            "assets/keep.part",
            "keep.part",
            "D.npy",
        ] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        assert_eq!(remove_stale_parts(dir.path()), 3);
        assert!(dir.path().join("assets/keep.part").exists());
        assert!(!dir.path().join("assets/.smspace-c3.part").exists());
        assert!(dir.path().join("keep.part").exists() && dir.path().join("D.npy").exists());
        assert!(!dir.path().join(".smspace-a1.part").exists());
    }

    #[test]
    fn a_waiting_writer_runs_once_the_first_is_done() {
        let dir = tempfile::tempdir().unwrap();
        let first = FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap();
        let path = dir.path().to_owned();
        let (told, heard) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            FolderLock::acquire(&path, BusyFolder::Wait, |lock| {
                told.send(lock.to_owned()).unwrap();
            })
            .map(|_| ())
        });
        // The waiter says it waits, and is still waiting while the lock is held.
        assert_eq!(heard.recv().unwrap(), lock_path(dir.path()));
        std::thread::sleep(std::time::Duration::from_millis(50));
        assert!(!waiter.is_finished());
        drop(first);
        waiter.join().unwrap().unwrap();
    }
}
