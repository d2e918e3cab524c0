//! Helpers of the tests that run the `scribblefield` binary on a capture (`source_size`,
//! `cli_export`): running it, reading its output, and writing a scene as an autolabel capture
//! folder to pack and to give as `--source`.
#![allow(dead_code)]
use std::path::Path;
use std::process::{Command, Output};

use image::{ImageBuffer, Luma};
use scribblefield::scene::Scene;

pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_scribblefield"))
        .args(args)
        .output()
        .expect("binary runs")
}

pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[track_caller]
pub fn ok(o: &Output) -> String {
    let t = text(o);
    assert!(o.status.success(), "{t}");
    t
}

#[track_caller]
pub fn fails(o: &Output, mentions: &[&str]) {
    let t = text(o);
    assert!(!o.status.success(), "expected failure, got success:\n{t}");
    assert!(!t.contains("panicked"), "panicked instead of reporting an error:\n{t}");
    for m in mentions {
        assert!(t.contains(m), "output should mention {m:?}:\n{t}");
    }
    eprintln!("refused as it should be: {}", t.lines().last().unwrap_or(""));
}

/// Writes `scene` as an autolabel capture folder (rgb/, depth/ in mm, pose/ world-to-camera,
/// intrinsics.txt, bbox.txt, gt/ with classes.txt).
pub fn write_autolabel(scene: &Scene, dir: &Path) {
    for sub in ["rgb", "depth", "pose", "gt"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    let k = scene.intrinsics;
    std::fs::write(
        dir.join("intrinsics.txt"),
        format!("{} 0 {}\n0 {} {}\n0 0 1\n", k.fx, k.cx, k.fy, k.cy),
    )
    .unwrap();
    let b = scene.bounds;
    std::fs::write(
        dir.join("bbox.txt"),
        format!(
            "{} {} {} {} {} {}\n",
            b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]
        ),
    )
    .unwrap();
    let names: Vec<&str> = scene.classes.iter().map(|c| c.name.as_str()).collect();
    std::fs::write(dir.join("classes.txt"), names.join("\n")).unwrap();
    let mm = scene.depth_scale / 0.001;
    for (i, f) in scene.frames.iter().enumerate() {
        f.rgb.save(dir.join(format!("rgb/{i:05}.png"))).unwrap();
        let d = f.depth.as_ref().unwrap();
        let depth: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(d.width(), d.height(), |x, y| {
            Luma([(f64::from(d.get_pixel(x, y).0[0]) * mm).round() as u16])
        });
        depth.save(dir.join(format!("depth/{i:05}.png"))).unwrap();
        f.gt.as_ref().unwrap().save(dir.join(format!("gt/{i:05}.png"))).unwrap();
        let m = f.pose.inverse().to_row_major();
        let rows: String = m
            .chunks(4)
            .map(|r| format!("{} {} {} {}\n", r[0], r[1], r[2], r[3]))
            .collect();
        std::fs::write(dir.join(format!("pose/{i:05}.txt")), rows).unwrap();
    }
}
