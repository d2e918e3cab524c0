//! Reading a file a user names (a checkpoint, a config, a capture's files) through caps: only a
//! regular file is opened, and at most `cap` bytes are read whatever its size says. A link to
//! `/dev/zero` reports size 0 and never ends; a FIFO blocks the open until a writer comes; a
//! file can grow between the size check and the read. So the kind is checked before opening
//! (following links, which users make on purpose), and the read is bounded by `Read::take`.
use std::fs::FileType;
use std::io::{self, Read};
use std::path::Path;

/// What a path that is not a regular file is, for messages.
pub fn kind_of(t: FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a folder"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

fn refused(kind: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{kind}, not a regular file; only regular files are read"),
    )
}

/// The bytes of the regular file at `path` (links followed), at most `cap` of them: a larger
/// file is refused, by its size before reading and by what was read after.
pub fn read_regular_file(path: &Path, cap: u64) -> io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(refused(kind_of(meta.file_type())));
    }
    let too_large = |len: u64| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{len} bytes or more, more than the {cap} read from such a file"),
        )
    };
    if meta.len() > cap {
        return Err(too_large(meta.len()));
    }
    let file = std::fs::File::open(path)?;
    // The path may have been replaced since it was checked.
    let opened = file.metadata()?;
    if !opened.is_file() {
        return Err(refused(kind_of(opened.file_type())));
    }
    let mut bytes = Vec::with_capacity(opened.len().min(cap) as usize);
    file.take(cap + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// [`read_regular_file`] as UTF-8 text.
pub fn read_regular_text(path: &Path, cap: u64) -> io::Result<String> {
    String::from_utf8(read_regular_file(path, cap)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "not UTF-8 text"))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_are_read_and_never_past_the_cap() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.txt");
        std::fs::write(&file, b"hello").unwrap();
        assert_eq!(read_regular_file(&file, 5).unwrap(), b"hello");
        let e = read_regular_file(&file, 4).unwrap_err().to_string();
        assert!(e.contains("more than the 4 read"), "{e}");
        let zero = dir.path().join("zero");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        let e = read_regular_file(&zero, 1 << 20).unwrap_err().to_string();
        assert!(e.contains("a character device, not a regular file"), "{e}");
        let e = read_regular_file(dir.path(), 1 << 20).unwrap_err().to_string();
        assert!(e.contains("a folder"), "{e}");
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let e = read_regular_file(&fifo, 1 << 20).unwrap_err().to_string();
            assert!(e.contains("a FIFO"), "{e}");
        }
    }
}
