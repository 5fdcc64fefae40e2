//! One writer per run folder: an advisory lock on `DIR/.smspace.lock`, held from before
//! `config.resolved.toml` is written until the run returns.
//!
//! Two `smspace run` into one folder would otherwise interleave their stage files and
//! manifests, so that a manifest could record another run's output under its own key
//! and every later run would reuse it. The lock is the operating system's (`flock` on
//! Unix, `LockFileEx` on Windows, through [`std::fs::File::lock`]), so it is released
//! when the process ends, however it ends: a killed run never leaves a stale lock.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::PipelineError;

/// Name of the lock file inside a run folder.
pub const LOCK_FILE: &str = ".smspace.lock";

/// What a run does when another process is writing its folder.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BusyFolder {
    /// Fail at once with [`PipelineError::Busy`] (the default).
    #[default]
    Refuse,
    /// Wait until the other run ends, then run.
    Wait,
}

/// The held lock; dropping it releases the folder.
#[derive(Debug)]
pub(super) struct FolderLock {
    _file: File,
}

impl FolderLock {
    /// Takes the lock of `dir` (which exists), waiting or refusing as `busy` says;
    /// `waiting` is called once before a wait.
    pub(super) fn acquire(
        dir: &Path,
        busy: BusyFolder,
        waiting: impl FnOnce(&Path),
    ) -> Result<Self, PipelineError> {
        let path = lock_path(dir);
        let lock_error = |reason| PipelineError::Lock {
            path: path.clone(),
            reason,
        };
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(lock_error)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => match busy {
                BusyFolder::Refuse => {
                    return Err(PipelineError::Busy {
                        dir: dir.to_owned(),
                        lock: path,
                    })
                }
                BusyFolder::Wait => {
                    waiting(&path);
                    file.lock().map_err(lock_error)?;
                }
            },
            Err(TryLockError::Error(reason)) => return Err(lock_error(reason)),
        }
        Ok(Self { _file: file })
    }
}

/// Removes the temporary files (`.smspace-*.part`, see [`crate::io::write_atomic`]) that
/// an interrupted writer left in `dir` and `dir/figures`. Only called while the folder's
/// lock is held, so no other run is writing them; returns how many were removed.
pub(super) fn remove_stale_parts(dir: &Path) -> usize {
    let mut removed = 0;
    for folder in [dir.to_owned(), dir.join("figures")] {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with(crate::io::TEMP_PREFIX)
                && name.ends_with(crate::io::TEMP_SUFFIX)
                && entry.file_type().is_ok_and(|t| t.is_file())
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
            Err(PipelineError::Busy { dir: busy, lock }) => {
                assert_eq!(busy, dir.path());
                assert_eq!(lock, lock_path(dir.path()));
            }
            other => panic!("expected Busy, got {other:?}"),
        }
        drop(first);
        FolderLock::acquire(dir.path(), BusyFolder::Refuse, |_| {}).unwrap();
    }

    #[test]
    fn stale_temporary_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("figures")).unwrap();
        for name in [
            ".smspace-a1.part",
            "figures/.smspace-b2.part",
            "keep.part",
            "D.npy",
        ] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        assert_eq!(remove_stale_parts(dir.path()), 2);
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
