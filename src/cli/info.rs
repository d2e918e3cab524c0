use std::path::Path;

use scribblefield::scene::Scene;

use super::CliResult;

pub fn run(archive: &Path) -> CliResult {
    let scene = scribblefield::scene::read_archive_path(archive)?;
    println!("archive:     {}", archive.display());
    print!("{}", scene.summary());
    for line in next_steps(&scene, &archive.display().to_string()) {
        println!("{line}");
    }
    Ok(())
}

/// What to run next on this archive: strokes to train from (its own, drawn from its ground
/// truth, or drawn in the page), then `segment`; and how to get the documented quality where
/// the archive has no feature codes.
fn next_steps(scene: &Scene, archive: &str) -> Vec<String> {
    let archive = if archive.contains(char::is_whitespace) {
        format!("'{archive}'")
    } else {
        archive.to_string()
    };
    let mut lines = Vec::new();
    let segment = match (&scene.labels, scene.has_gt()) {
        (Some(_), _) => format!("segment {archive} -o masks/   (trains on the strokes it holds)"),
        (None, has_gt) => {
            lines.push(if has_gt {
                format!("next:        scribblefield scribble-from-gt {archive} --frames 0 -o labels.json   (strokes from its ground truth)")
            } else {
                "next:        draw strokes in the page (scribblefield serve www, open this archive) and save labels.json".to_string()
            });
            format!("segment {archive} --labels labels.json -o masks/")
        }
    };
    let lead = if lines.is_empty() { "next:  " } else { "then:  " };
    lines.push(format!("{lead}      scribblefield {segment}"));
    if scene.features.is_none() {
        lines.push(
            "note:        no feature codes (packed with --no-features?): the documented figures use the baseline codes `pack` bakes"
                .to_string(),
        );
    }
    lines
}
