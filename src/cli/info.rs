use std::path::Path;

use super::CliResult;

pub fn run(archive: &Path) -> CliResult {
    let scene = scribblefield::scene::read_archive_path(archive)?;
    println!("archive:     {}", archive.display());
    print!("{}", scene.summary());
    Ok(())
}
