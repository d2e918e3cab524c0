//! The lock a simulated-user run holds on its output folder: `simulate.lock`, locked with the
//! operating system's advisory file lock (`File::try_lock`: `flock` on Unix, `LockFileEx` on
//! Windows) and holding the holder's process id for the message. The lock goes with the process:
//! one that dies or is killed leaves a file that is not locked, which the next run takes over.
//! The file is removed when the run ends.
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use super::{LOCK_FILE, SimulateError, io_error};

pub(super) struct RunLock {
    path: PathBuf,
    _file: File,
}

impl RunLock {
    pub(super) fn acquire(out: &Path) -> Result<RunLock, SimulateError> {
        let path = out.join(LOCK_FILE);
        // A holder that ends between our open and our lock has removed the file we locked:
        // then lock the one at the path again.
        for _ in 0..3 {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(io_error(&path))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    let mut holder = String::new();
                    let _ = file.read_to_string(&mut holder);
                    let pid = holder.trim();
                    return Err(SimulateError::Output {
                        path,
                        problem: format!(
                            "another run (process {pid}) is writing this folder; wait for it, or delete the lock file if no such process runs"
                        ),
                    });
                }
                Err(TryLockError::Error(e)) => return Err(io_error(&path)(e)),
            }
            if !same_file(&file, &path) {
                continue;
            }
            file.set_len(0).map_err(io_error(&path))?;
            file.rewind().map_err(io_error(&path))?;
            write!(file, "{}", std::process::id()).map_err(io_error(&path))?;
            return Ok(RunLock { path, _file: file });
        }
        Err(SimulateError::Output {
            path,
            problem: "could not take the lock".into(),
        })
    }
}

/// Whether `path` still names the file `file` has open.
#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_file: &File, path: &Path) -> bool {
    path.exists()
}

impl Drop for RunLock {
    fn drop(&mut self) {
        // Removed while still locked, so no other run takes the file over in between.
        let _ = std::fs::remove_file(&self.path);
    }
}
