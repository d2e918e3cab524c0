//! The ARKitScenes importer on the YCB clip of ../shared/data written in ARKitScenes' layout
//! (no ARKitScenes scene is in ../shared/data): it must pack what the clip packs from its own
//! autolabel folder, from disk and from memory, and name every bad file.
mod import_common;

use std::path::Path;
use std::rc::Rc;

use glam::{DMat3, DQuat};
use import_common::*;
use scribblefield::pause::{NoPause, run_to_end};
use scribblefield::scene::Scene;
use scribblefield::scene::import::{ImportOptions, Layout, detect_layout, import, import_files};

const YCB: &str = "ycb-video-0000";
const VIDEO: &str = "ycb0000";
const FRAMES: usize = 10;

/// Frame `i`'s timestamp: 10 Hz, as ARKitScenes' frames, from an arbitrary start.
fn time(i: usize) -> f64 {
    3054.713 + 0.1 * i as f64
}

fn stem(i: usize) -> String {
    format!("{VIDEO}_{:.3}", time(i))
}

/// The YCB clip in ARKitScenes' layout: colour and depth copied (8-bit RGB and uint16 mm PNGs
/// already), the clip's K as a `.pincam` per frame, its world-to-camera poses as angle-axis
/// `.traj` lines. The trajectory's clock is offset from the names by 2 ms, as ARKit's
/// timestamps are rounded in the names, and has a pose between frames that no frame takes.
fn write_arkit(ycb: &Path, to: &Path) {
    let mut traj = String::new();
    for i in 0..FRAMES {
        let from = format!("{i:05}");
        let s = stem(i);
        copy_file(
            &ycb.join(format!("rgb/{from}.png")),
            &to.join(format!("lowres_wide/{s}.png")),
        );
        copy_file(
            &ycb.join(format!("depth/{from}.png")),
            &to.join(format!("lowres_depth/{s}.png")),
        );
        write(
            &to.join(format!("lowres_wide_intrinsics/{s}.pincam")),
            "640 480 1066.778 1067.487 312.9869 241.3109\n",
        );
        let m = read_matrix(&ycb.join(format!("pose/{from}.txt")));
        let (axis, angle) = DQuat::from_mat3(&DMat3::from_mat4(m.0)).normalize().to_axis_angle();
        let r = axis * angle;
        let t = m.translation();
        traj += &format!(
            "{:.6} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12}\n",
            time(i) + 0.002,
            r.x,
            r.y,
            r.z,
            t.x,
            t.y,
            t.z
        );
        traj += &format!("{:.6} 0 0 0 0 0 0\n", time(i) + 0.05);
    }
    write(&to.join("lowres_wide.traj"), traj);
}

fn imported(dir: &Path, opts: &ImportOptions) -> scribblefield::scene::import::Imported {
    import(dir, opts, &mut |_, _| {}).unwrap()
}

/// The same frames, cameras and images, poses within 1e-4 (the `.traj` goes through angle-axis).
fn assert_same_frames(arkit: &Scene, own: &Scene) {
    assert_eq!(arkit.frames.len(), own.frames.len());
    assert_eq!((arkit.width, arkit.height), (own.width, own.height));
    assert_eq!(arkit.intrinsics, own.intrinsics);
    assert_eq!(arkit.depth_scale, own.depth_scale);
    for (i, (a, o)) in arkit.frames.iter().zip(&own.frames).enumerate() {
        assert!(
            a.pose.0.abs_diff_eq(o.pose.0, 1e-4),
            "frame {i}: {} vs {}",
            a.pose.0,
            o.pose.0
        );
        assert!(a.rgb == o.rgb, "colour of frame {i} differs");
        assert!(a.depth == o.depth, "depth of frame {i} differs");
        assert!(a.gt.is_none());
    }
}

#[test]
fn the_ycb_clip_packs_the_same_from_arkitscenes_layout() {
    let Some(ycb) = real_data(YCB) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("41069025");
    write_arkit(&ycb, &dir);
    assert_eq!(detect_layout(&dir).unwrap(), Layout::ArkitScenes);

    let arkit = imported(&dir, &ImportOptions::default());
    assert_eq!(arkit.layout, Layout::ArkitScenes);
    assert!(arkit.warnings.is_empty(), "{:?}", arkit.warnings);
    let own = imported(&ycb, &ImportOptions::default());
    assert_same_frames(&arkit.scene, &own.scene);
    let s = &arkit.scene;
    assert_eq!(s.frames[0].source.as_deref(), Some(stem(0).as_str()));
    assert_eq!(s.frames[9].source.as_deref(), Some(stem(9).as_str()));
    assert_eq!(s.provenance.importer, "arkitscenes");
    // No bbox.txt here: the bounds come from depth, and must hold the clip's own box's centre.
    let (a, o) = (s.bounds, own.scene.bounds);
    for axis in 0..3 {
        let centre = (o.min[axis] + o.max[axis]) / 2.0;
        assert!(a.min[axis] < centre && centre < a.max[axis], "{a:?} vs {o:?}");
    }

    // The options pick and scale the same frames as for the clip's own folder.
    let opts = ImportOptions {
        every: 2,
        max_frames: Some(3),
        max_size: Some(320),
        ..Default::default()
    };
    let arkit = imported(&dir, &opts);
    let own = imported(&ycb, &opts);
    assert_same_frames(&arkit.scene, &own.scene);
    let names: Vec<_> = arkit.scene.frames.iter().map(|f| f.source.clone().unwrap()).collect();
    assert_eq!(names, [stem(0), stem(2), stem(4)]);

    // The page reads the same folder from memory into the same scene.
    let memory = run_to_end(import_files(
        Rc::new(folder_in_memory(&dir)),
        &opts,
        &mut |_, _| {},
        &mut NoPause,
    ))
    .unwrap();
    assert_eq!(memory.layout, Layout::ArkitScenes);
    assert_same_frames(&memory.scene, &own.scene);
}

/// Frame 0's ground truth carried to frames 1-9 through each packing's depth, intrinsics and
/// poses (back-projected, moved, projected; the nearest wins where several land on one pixel)
/// labels those frames as well in both: mean IoU against their own ground truth within 0.02.
/// Training a field (the GPU) is not needed to check what the importer decides: where each
/// pixel lies.
#[test]
fn frame_0_carried_to_the_other_frames_agrees_with_the_clip_packed_from_its_folder() {
    let Some(ycb) = real_data(YCB) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("41069025");
    write_arkit(&ycb, &dir);
    let opts = ImportOptions {
        max_size: Some(160),
        ..Default::default()
    };
    let own = imported(&ycb, &opts).scene;
    let arkit = imported(&dir, &opts).scene;
    let classes = own.classes.len();
    let source = own.frames[0].gt.as_ref().unwrap();
    let miou = |scene: &Scene| carried_ground_truth_iou(scene, source, &own, classes);
    let (a, o) = (miou(&arkit), miou(&own));
    eprintln!("mean IoU of frame 0's ground truth carried to frames 1-9: ARKitScenes layout {a:.4}, own folder {o:.4}");
    assert!(o > 0.5, "frame 0 carries too little to compare: {o}");
    assert!((a - o).abs() <= 0.02, "{a} vs {o}");
}

#[test]
fn bad_scenes_are_refused_naming_the_file() {
    let Some(ycb) = real_data(YCB) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let fresh = |name: &str| {
        let dir = tmp.path().join(name);
        write_arkit(&ycb, &dir);
        dir
    };

    let dir = fresh("no-traj");
    std::fs::remove_file(dir.join("lowres_wide.traj")).unwrap();
    assert!(error_naming(&dir, "lowres_wide.traj").contains("missing"));

    let dir = fresh("bad-traj");
    let traj = std::fs::read_to_string(dir.join("lowres_wide.traj")).unwrap();
    write(
        &dir.join("lowres_wide.traj"),
        traj.replacen(" 0 0 0 0 0 0\n", " 0 0 0 0 nan 0\n", 1),
    );
    let e = error_naming(&dir, "lowres_wide.traj");
    assert!(
        e.contains("line 2") && e.contains("ty = nan is not a finite number"),
        "{e}"
    );
    write(
        &dir.join("lowres_wide.traj"),
        traj.replacen(" 0 0 0 0 0 0\n", " 0 0 0 0 0\n", 1),
    );
    let e = error_naming(&dir, "lowres_wide.traj");
    assert!(e.contains("line 2") && e.contains("found 6 words"), "{e}");

    let dir = fresh("other-traj");
    write(&dir.join("lowres_wide.traj"), "12.5 0 0 0 0 0 0\n");
    let e = error_naming(&dir, "lowres_wide.traj");
    assert!(e.contains("no pose within 5 ms of any of the 10 frames"), "{e}");

    let dir = fresh("no-depth");
    std::fs::remove_file(dir.join(format!("lowres_depth/{}.png", stem(3)))).unwrap();
    let e = error_naming(&dir, &format!("lowres_depth/{}.png", stem(3)));
    assert!(
        e.contains("missing") && e.contains("10 colour frames, 9 in lowres_depth/"),
        "{e}"
    );

    let dir = fresh("no-pincam");
    std::fs::remove_file(dir.join(format!("lowres_wide_intrinsics/{}.pincam", stem(5)))).unwrap();
    assert!(error_naming(&dir, &format!("lowres_wide_intrinsics/{}.pincam", stem(5))).contains("missing"));

    let dir = fresh("bad-pincam");
    write(
        &dir.join(format!("lowres_wide_intrinsics/{}.pincam", stem(0))),
        "640 480 1066 1067 inf 241\n",
    );
    let e = error_naming(&dir, &format!("{}.pincam", stem(0)));
    assert!(e.contains("line 1") && e.contains("cx = inf"), "{e}");
    write(
        &dir.join(format!("lowres_wide_intrinsics/{}.pincam", stem(0))),
        "640 400 1066 1067 312 241\n",
    );
    let e = error_naming(&dir, &format!("{}.pincam", stem(0)));
    assert!(e.contains("640x400") && e.contains("640x480"), "{e}");

    let dir = fresh("other-camera");
    write(
        &dir.join(format!("lowres_wide_intrinsics/{}.pincam", stem(4))),
        "640 480 900 900 312 241\n",
    );
    let e = error_naming(&dir, &format!("{}.pincam", stem(4)));
    assert!(
        e.contains("another camera") && e.contains(&format!("{}.pincam", stem(0))),
        "{e}"
    );

    let dir = fresh("unnamed-frame");
    copy_file(&ycb.join("rgb/00000.png"), &dir.join("lowres_wide/frame.png"));
    assert!(error_naming(&dir, "lowres_wide/frame.png").contains("<video_id>_<timestamp>.png"));

    // Frames the trajectory does not reach are skipped and counted, as tracking starts late.
    let dir = fresh("late-tracking");
    let traj: String = traj.lines().skip(4).map(|l| format!("{l}\n")).collect();
    write(&dir.join("lowres_wide.traj"), traj);
    let got = imported(&dir, &ImportOptions::default());
    assert_eq!(got.scene.frames.len(), 8);
    assert_eq!(got.scene.frames[0].source.as_deref(), Some(stem(2).as_str()));
    let w = got.warnings.join("\n");
    assert!(
        w.contains("skipped 2 of 10 frames with no pose within 5 ms") && w.contains(&stem(0)),
        "{w}"
    );

    // The page names the same file, by the folder's name.
    let dir = fresh("memory");
    std::fs::remove_file(dir.join("lowres_wide.traj")).unwrap();
    let e = run_to_end(import_files(
        Rc::new(folder_in_memory(&dir)),
        &ImportOptions::default(),
        &mut |_, _| {},
        &mut NoPause,
    ))
    .map(|_| ())
    .unwrap_err()
    .to_string();
    assert!(e.contains("memory/lowres_wide.traj: missing"), "{e}");
}
