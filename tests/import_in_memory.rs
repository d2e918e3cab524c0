//! The importers reading a capture held in memory (what the page packs: a folder's files or a
//! zip of them) give the scene, and the errors, they give reading the same capture from disk.
mod import_common;

use std::rc::Rc;

use import_common::*;
use scribblefield::pause::{NoPause, run_to_end};
use scribblefield::scene::Scene;
use scribblefield::scene::import::{ImportOptions, MemoryFiles, import, import_files};
use tempfile::TempDir;

fn from_memory(files: MemoryFiles, opts: &ImportOptions) -> Result<Scene, String> {
    run_to_end(import_files(Rc::new(files), opts, &mut |_, _| {}, &mut NoPause))
        .map(|i| i.scene)
        .map_err(|e| e.to_string())
}

fn same_scene(a: &Scene, b: &Scene) {
    assert_eq!((a.width, a.height, a.frames.len()), (b.width, b.height, b.frames.len()));
    assert_eq!(a.intrinsics, b.intrinsics);
    assert_eq!(a.bounds, b.bounds);
    assert_eq!(a.classes, b.classes);
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        assert_eq!(fa.source, fb.source);
        assert_eq!(fa.pose, fb.pose);
        assert!(fa.rgb == fb.rgb, "colour of {:?} differs", fa.source);
        assert!(fa.depth == fb.depth, "depth of {:?} differs", fa.source);
        assert!(fa.gt == fb.gt, "ground truth of {:?} differs", fa.source);
    }
}

#[test]
fn the_colmap_capture_imports_the_same_from_memory_as_from_disk() {
    let Some(dir) = real_data("alexander-colmap") else {
        return;
    };
    let opts = ImportOptions {
        max_size: Some(64),
        every: 13,
        ..Default::default()
    };
    let disk = import(&dir, &opts, &mut |_, _| {}).unwrap().scene;
    let memory = from_memory(folder_in_memory(&dir), &opts).unwrap();
    same_scene(&disk, &memory);
    assert_eq!(memory.provenance.source, "alexander-colmap");
}

#[test]
fn a_zip_of_a_capture_imports_like_its_folder() {
    let Some(dir) = real_data("alexander-colmap") else {
        return;
    };
    let opts = ImportOptions {
        max_size: Some(48),
        every: 26,
        ..Default::default()
    };
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let mut stack = vec![(dir.clone(), "alexander-colmap".to_string())];
    while let Some((folder, prefix)) = stack.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            let name = format!("{prefix}/{}", path.file_name().unwrap().to_string_lossy());
            if path.is_dir() {
                stack.push((path, name));
            } else {
                zip.start_file(name, zip::write::SimpleFileOptions::default()).unwrap();
                std::io::Write::write_all(&mut zip, &std::fs::read(&path).unwrap()).unwrap();
            }
        }
    }
    let bytes = zip.finish().unwrap().into_inner();
    let from_zip = from_memory(MemoryFiles::from_zip("alexander-colmap.zip", &bytes).unwrap(), &opts).unwrap();
    same_scene(&import(&dir, &opts, &mut |_, _| {}).unwrap().scene, &from_zip);
}

/// A file of a test capture: its path in the capture folder and its bytes.
type CaptureFile<'a> = (&'a str, &'a [u8]);

/// Bad captures get the command line's message, with the folder's name where it has its path.
#[test]
fn bad_captures_get_the_command_lines_errors() {
    let tmp = TempDir::new().unwrap();
    let cases: [(&str, &[CaptureFile]); 3] = [
        ("holiday", &[("photo.jpg", b"\xff\xd8 not really")]),
        ("broken-json", &[("transforms.json", b"{\"frames\": [")]),
        (
            "half-colmap",
            &[("images/a.jpg", b"x"), ("sparse/0/cameras.txt", b"# no cameras\n")],
        ),
    ];
    for (name, files) in cases {
        let dir = tmp.path().join(name);
        let mut memory = MemoryFiles::new();
        for (path, bytes) in files {
            let p = dir.join(path);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(&p, bytes).unwrap();
            memory.add(&format!("{name}/{path}"), bytes.to_vec()).unwrap();
        }
        let disk = import(&dir, &ImportOptions::default(), &mut |_, _| {})
            .err()
            .unwrap()
            .to_string();
        let in_memory = from_memory(memory, &ImportOptions::default()).err().unwrap();
        // The command line names the folder by the path it was given; the page by its name.
        let prefix = format!("{}/", tmp.path().display());
        assert_eq!(disk.replace(&prefix, ""), in_memory, "{name}");
        eprintln!("{name}: {in_memory}");
    }
}
