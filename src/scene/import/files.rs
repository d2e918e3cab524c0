//! Where the importers read a capture's files: the disk (the command line, the tests) or a set
//! of files held in memory (the page, which is handed a picked or dropped folder, or a zip of
//! one, as bytes: wasm has no file system).
//!
//! The importers ask through the free functions here (`read`, `metadata`, `read_dir`) and the
//! [`CapturePath`] methods (`is_capture_file`, `is_capture_dir`) instead of `std::fs`, so one
//! importer serves both. Which source answers is set per thread for the duration of each poll of
//! an import ([`reading_from`]); with none set it is the disk. A scoped setting rather than a
//! parameter keeps every importer's helpers (dozens of functions that take a path) as they were,
//! and setting it per poll rather than once keeps it right when the page interleaves an import
//! that pauses with other work on its one thread.
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::future::{Future, poll_fn};
use std::io;
use std::path::{Component, Path, PathBuf};
use std::pin::pin;
use std::rc::Rc;

use crate::scene::archive::limits;
use crate::scene::error::{Result, SceneError};

/// What an importer needs of a file or folder without reading it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Meta {
    pub is_dir: bool,
    /// Bytes (0 for a folder).
    pub len: u64,
    /// The path itself is a symbolic link (what it says of the target: the fields above). The
    /// walks through folders do not follow links to folders (see `colmap::photos_under`).
    pub is_link: bool,
}

impl Meta {
    pub fn is_file(&self) -> bool {
        !self.is_dir
    }
    pub fn len(&self) -> u64 {
        self.len
    }
}

/// A capture's files, wherever they are. Errors are `io::Error`s, as the disk's are, so the
/// importers' messages (which name the path) read the same from both sources.
pub trait CaptureFiles {
    fn metadata(&self, path: &Path) -> io::Result<Meta>;
    /// The whole file, refused when it has more than `cap` bytes (counted as they are read).
    fn read(&self, path: &Path, cap: u64) -> io::Result<Vec<u8>>;
    /// The paths of the entries directly in `dir` (files and folders).
    fn read_dir(&self, dir: &Path) -> io::Result<Vec<PathBuf>>;
}

/// The file system.
pub struct Disk;

impl CaptureFiles for Disk {
    fn metadata(&self, path: &Path) -> io::Result<Meta> {
        let m = std::fs::metadata(path)?;
        let is_link = std::fs::symlink_metadata(path)?.file_type().is_symlink();
        Ok(Meta {
            is_dir: m.is_dir(),
            len: if m.is_dir() { 0 } else { m.len() },
            is_link,
        })
    }
    /// Only a regular file is read (a link to one is followed: captures link folders and
    /// files in on purpose): a FIFO would block forever, `/dev/zero` never ends.
    fn read(&self, path: &Path, cap: u64) -> io::Result<Vec<u8>> {
        crate::bounded_read::read_regular_file(path, cap)
    }
    fn read_dir(&self, dir: &Path) -> io::Result<Vec<PathBuf>> {
        std::fs::read_dir(dir)?.map(|e| e.map(|e| e.path())).collect()
    }
}

thread_local! {
    static CURRENT: RefCell<Option<Rc<dyn CaptureFiles>>> = const { RefCell::new(None) };
}

/// Runs `work` (an import) with its files read from `files`: the source is set for each poll of
/// `work` and restored after it, so other work on the thread between polls reads its own.
pub async fn reading_from<T>(files: Rc<dyn CaptureFiles>, work: impl Future<Output = T>) -> T {
    let mut work = pin!(work);
    poll_fn(|cx| {
        let _set = SetSource::new(files.clone());
        work.as_mut().poll(cx)
    })
    .await
}

/// Sets the thread's source until dropped (also when the poll panics), then puts back what was
/// there.
struct SetSource(Option<Rc<dyn CaptureFiles>>);

impl SetSource {
    fn new(files: Rc<dyn CaptureFiles>) -> SetSource {
        SetSource(CURRENT.with(|c| c.replace(Some(files))))
    }
}

impl Drop for SetSource {
    fn drop(&mut self) {
        let previous = self.0.take();
        CURRENT.with(|c| *c.borrow_mut() = previous);
    }
}

fn with_source<R>(f: impl FnOnce(&dyn CaptureFiles) -> R) -> R {
    let current = CURRENT.with(|c| c.borrow().clone());
    match current {
        Some(files) => f(&*files),
        None => f(&Disk),
    }
}

/// Whether the capture's files are read from the disk rather than a set held in memory.
#[cfg(not(target_arch = "wasm32"))]
pub(super) fn on_disk() -> bool {
    CURRENT.with(|c| c.borrow().is_none())
}

pub(super) fn metadata(path: &Path) -> io::Result<Meta> {
    with_source(|f| f.metadata(path))
}

/// The file at `path`, at most `cap` bytes of it (each caller's cap is what its kind of file
/// can hold).
pub(super) fn read(path: &Path, cap: u64) -> io::Result<Vec<u8>> {
    with_source(|f| f.read(path, cap))
}

pub(super) fn read_dir(dir: &Path) -> io::Result<Vec<PathBuf>> {
    with_source(|f| f.read_dir(dir))
}

/// `is_file` and `is_dir` asked of the capture's source rather than the disk.
pub(super) trait CapturePath {
    fn is_capture_file(&self) -> bool;
    fn is_capture_dir(&self) -> bool;
}

impl CapturePath for Path {
    fn is_capture_file(&self) -> bool {
        metadata(self).is_ok_and(|m| m.is_file())
    }
    fn is_capture_dir(&self) -> bool {
        metadata(self).is_ok_and(|m| m.is_dir)
    }
}

/// Names that are never part of a capture: what macOS and Windows leave in folders and zips.
fn is_junk(name: &str) -> bool {
    name == "__MACOSX" || name == ".DS_Store" || name == "Thumbs.db" || name.starts_with("._")
}

/// A capture held in memory: files under one root folder (its name is the capture's name in
/// messages, as the folder's path is on the command line).
#[derive(Default)]
pub struct MemoryFiles {
    files: BTreeMap<PathBuf, Vec<u8>>,
    dirs: BTreeSet<PathBuf>,
    bytes: u64,
}

impl MemoryFiles {
    /// Files given by their paths relative to the folder the user picked, with `/` separators,
    /// the first component being that folder (a browser's `webkitRelativePath`:
    /// `capture/images/0001.jpg`). A path that is absolute or climbs with `..` is refused:
    /// nothing outside the picked folder can be named.
    pub fn new() -> MemoryFiles {
        MemoryFiles::default()
    }

    /// Adds one file; `relative` as in [`MemoryFiles::new`]. Junk files (`.DS_Store`,
    /// `__MACOSX/`) are left out.
    pub fn add(&mut self, relative: &str, bytes: Vec<u8>) -> Result<()> {
        let mut path = PathBuf::new();
        for part in relative.split(['/', '\\']) {
            match part {
                "" | "." => {}
                ".." => {
                    return Err(SceneError::invalid(
                        relative,
                        "a path in the capture climbs out of it with ..",
                    ));
                }
                _ if is_junk(part) => return Ok(()),
                _ => path.push(part),
            }
        }
        if path.as_os_str().is_empty() || relative.starts_with(['/', '\\']) {
            return Err(SceneError::invalid(relative, "not a file path inside the capture"));
        }
        let total = self.bytes + bytes.len() as u64;
        if total > MAX_CAPTURE_BYTES {
            return Err(SceneError::invalid(
                relative,
                format!(
                    "the capture's files add up to more than this page packs ({MAX_CAPTURE_BYTES} bytes at most); \
                     pack it with the command line (`scribblefield pack`)"
                ),
            ));
        }
        if self.dirs.contains(&path) {
            return Err(SceneError::invalid(relative, "both a file and a folder in the capture"));
        }
        let mut parent = path.parent();
        while let Some(p) = parent.filter(|p| !p.as_os_str().is_empty()) {
            if self.files.contains_key(p) {
                return Err(SceneError::invalid(relative, "inside a path that is a file"));
            }
            self.dirs.insert(p.to_path_buf());
            parent = p.parent();
        }
        self.bytes = total;
        self.files.insert(path, bytes);
        Ok(())
    }

    /// The files of a zip of a capture (`name`, for messages). Entries all under one folder
    /// have that folder as the capture's root; otherwise the zip's name without `.zip` is.
    pub fn from_zip(name: &str, bytes: &[u8]) -> Result<MemoryFiles> {
        use std::io::Read;
        let zip_error = |source| SceneError::Zip {
            file: name.into(),
            source,
        };
        let mut archive = zip::ZipArchive::new(io::Cursor::new(bytes)).map_err(zip_error)?;
        if archive.len() > limits::MAX_ENTRIES {
            return Err(SceneError::invalid(
                name,
                format!(
                    "{} entries; a capture zip holds at most {}",
                    archive.len(),
                    limits::MAX_ENTRIES
                ),
            ));
        }
        let mut entries = Vec::new();
        let mut declared: u64 = 0;
        for i in 0..archive.len() {
            let mut entry = archive.by_index(i).map_err(zip_error)?;
            if entry.is_dir() {
                continue;
            }
            let entry_name = entry.name().map_err(zip_error)?.to_string();
            declared += entry.size();
            if declared > MAX_CAPTURE_BYTES {
                return Err(SceneError::invalid(
                    name,
                    format!(
                        "its files add up to more than this page packs ({MAX_CAPTURE_BYTES} bytes at most); \
                         pack it with the command line (`scribblefield pack`)"
                    ),
                ));
            }
            // Read no more than the entry declares: a crafted entry cannot inflate past it.
            let size = entry.size();
            let mut data = Vec::with_capacity(size as usize);
            (&mut entry)
                .take(size)
                .read_to_end(&mut data)
                .map_err(|e| SceneError::invalid(format!("{name}: {entry_name}"), format!("cannot unpack: {e}")))?;
            entries.push((entry_name, data));
        }
        let wanted: Vec<&(String, Vec<u8>)> = entries
            .iter()
            .filter(|(n, _)| !n.split(['/', '\\']).any(is_junk))
            .collect();
        let first = |n: &str| {
            n.split(['/', '\\'])
                .find(|p| !p.is_empty() && *p != ".")
                .map(str::to_string)
        };
        let roots: BTreeSet<Option<String>> = wanted
            .iter()
            .map(|(n, _)| n.contains(['/', '\\']).then(|| first(n)).flatten())
            .collect();
        let one_root = roots.len() == 1 && roots.iter().all(Option::is_some);
        let stem = name
            .rsplit(['/', '\\'])
            .next()
            .unwrap_or(name)
            .trim_end_matches(".zip")
            .trim_end_matches(".ZIP");
        let stem = if stem.is_empty() || stem == "." || stem == ".." {
            "capture"
        } else {
            stem
        };
        let mut files = MemoryFiles::new();
        for (entry_name, data) in entries {
            let relative = if one_root {
                entry_name
            } else {
                format!("{stem}/{entry_name}")
            };
            files.add(&relative, data)?;
        }
        Ok(files)
    }

    /// The folder to import: the one folder every file is under. `None` when the files are
    /// spread over several (a browser's folder picker never does that).
    pub fn root(&self) -> Option<PathBuf> {
        let mut roots = self.files.keys().map(|p| p.components().next());
        let first = roots.next()??;
        let root = PathBuf::from(first.as_os_str());
        (self.dirs.contains(&root) && roots.all(|r| r == Some(first))).then_some(root)
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Bytes of all files.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

/// Shows the file count and size, not the bytes.
impl std::fmt::Debug for MemoryFiles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MemoryFiles({} files, {} bytes)", self.files.len(), self.bytes)
    }
}

/// Largest capture the page holds in memory to pack: wasm32 memory ends at 4 GiB and the
/// decoded frames, the archive and the scene decoded from it need room beside the files.
pub const MAX_CAPTURE_BYTES: u64 = 1 << 30;

/// `path` as the key it would have (`.` components dropped), or `None` for a path that cannot
/// be in memory (absolute, or with `..`).
fn key(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            Component::Normal(p) => out.push(p),
            Component::CurDir => {}
            _ => return None,
        }
    }
    Some(out)
}

fn not_found(path: &Path) -> io::Error {
    io::Error::new(
        io::ErrorKind::NotFound,
        format!("no such file in the capture: {}", path.display()),
    )
}

impl CaptureFiles for MemoryFiles {
    fn metadata(&self, path: &Path) -> io::Result<Meta> {
        let k = key(path).ok_or_else(|| not_found(path))?;
        if let Some(bytes) = self.files.get(&k) {
            return Ok(Meta {
                is_dir: false,
                len: bytes.len() as u64,
                is_link: false,
            });
        }
        if self.dirs.contains(&k) {
            return Ok(Meta {
                is_dir: true,
                len: 0,
                is_link: false,
            });
        }
        Err(not_found(path))
    }

    fn read(&self, path: &Path, cap: u64) -> io::Result<Vec<u8>> {
        let k = key(path).ok_or_else(|| not_found(path))?;
        match self.files.get(&k) {
            Some(bytes) if bytes.len() as u64 > cap => Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{} bytes, more than the {cap} read from such a file", bytes.len()),
            )),
            Some(bytes) => Ok(bytes.clone()),
            None if self.dirs.contains(&k) => Err(io::Error::new(io::ErrorKind::IsADirectory, "is a folder")),
            None => Err(not_found(path)),
        }
    }

    fn read_dir(&self, dir: &Path) -> io::Result<Vec<PathBuf>> {
        let k = key(dir).ok_or_else(|| not_found(dir))?;
        if !self.dirs.contains(&k) {
            return Err(not_found(dir));
        }
        // Entries are listed under the path the caller gave, as `std::fs::read_dir` does.
        let direct = |p: &PathBuf| p.parent() == Some(k.as_path());
        Ok(self
            .files
            .keys()
            .filter(|p| direct(p))
            .chain(self.dirs.iter().filter(|p| direct(p)))
            .filter_map(|p| p.file_name())
            .map(|n| dir.join(n))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn capture() -> MemoryFiles {
        let mut f = MemoryFiles::new();
        f.add("cap/images/a.jpg", vec![1, 2]).unwrap();
        f.add("cap/images/b.jpg", vec![3]).unwrap();
        f.add("cap/sparse/0/cameras.txt", b"# none".to_vec()).unwrap();
        f.add("cap/.DS_Store", vec![0]).unwrap();
        f
    }

    #[test]
    fn memory_files_answer_as_a_folder_would() {
        let f = capture();
        assert_eq!(f.root(), Some(PathBuf::from("cap")));
        assert_eq!(f.len(), 3);
        assert!(f.metadata(Path::new("cap/images")).unwrap().is_dir);
        assert_eq!(f.metadata(Path::new("cap/./images/a.jpg")).unwrap().len(), 2);
        assert_eq!(
            f.metadata(Path::new("cap/nope")).unwrap_err().kind(),
            io::ErrorKind::NotFound
        );
        let mut listed = f.read_dir(Path::new("cap")).unwrap();
        listed.sort();
        assert_eq!(listed, [PathBuf::from("cap/images"), PathBuf::from("cap/sparse")]);
        assert_eq!(f.read(Path::new("cap/images/b.jpg"), 1).unwrap(), [3]);
        assert!(f.read(Path::new("cap/images/a.jpg"), 1).is_err());
    }

    #[test]
    fn paths_out_of_the_capture_are_refused() {
        let mut f = MemoryFiles::new();
        let e = f.add("cap/../etc/passwd", vec![]).unwrap_err().to_string();
        assert!(e.contains("climbs out"), "{e}");
        assert!(f.add("/etc/passwd", vec![]).is_err());
        f.add("cap/a", vec![]).unwrap();
        assert!(f.add("cap/a/b", vec![]).unwrap_err().to_string().contains("is a file"));
    }

    #[test]
    fn a_zip_gets_one_root() {
        use std::io::Write;
        let zip_of = |names: &[&str]| {
            let mut w = zip::ZipWriter::new(io::Cursor::new(Vec::new()));
            for n in names {
                w.start_file(*n, zip::write::SimpleFileOptions::default()).unwrap();
                w.write_all(b"x").unwrap();
            }
            w.finish().unwrap().into_inner()
        };
        let f = MemoryFiles::from_zip("c.zip", &zip_of(&["lego/transforms_train.json", "__MACOSX/lego/x"])).unwrap();
        assert_eq!(f.root(), Some(PathBuf::from("lego")));
        let f = MemoryFiles::from_zip("my scan.zip", &zip_of(&["color/0.jpg", "intrinsic/k.txt"])).unwrap();
        assert_eq!(f.root(), Some(PathBuf::from("my scan")));
        assert!(f.metadata(Path::new("my scan/color/0.jpg")).is_ok());
        let e = MemoryFiles::from_zip("bad.zip", b"not a zip").unwrap_err().to_string();
        assert!(e.starts_with("bad.zip: not a readable zip archive"), "{e}");
    }

    #[test]
    fn the_source_is_set_per_poll() {
        let f: Rc<dyn CaptureFiles> = Rc::new(capture());
        let seen = crate::pause::run_to_end(reading_from(f, async {
            Path::new("cap/images/a.jpg").is_capture_file()
        }));
        assert!(seen);
        // Back to the disk afterwards.
        assert!(!Path::new("cap/images/a.jpg").is_capture_file());
    }
}
