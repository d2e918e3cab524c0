use super::*;
use crate::pause::{CountPauses, run_to_end};
use crate::scene::read_archive;

/// A transforms.json capture of `n` 16x12 frames, in memory.
fn capture(n: usize) -> MemoryFiles {
    let mut files = MemoryFiles::new();
    let mut frames = Vec::new();
    for i in 0..n {
        let img = image::RgbImage::from_fn(16, 12, |x, y| {
            image::Rgb([(x * 15) as u8, (y * 20) as u8, (i * 40) as u8])
        });
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        files.add(&format!("cap/images/{i}.png"), png).unwrap();
        frames.push(serde_json::json!({
            "file_path": format!("images/{i}.png"),
            "transform_matrix": [[1, 0, 0, i as f64 * 0.1], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]],
        }));
    }
    let json = serde_json::json!({ "camera_angle_x": 0.8, "frames": frames });
    files
        .add("cap/transforms.json", serde_json::to_vec(&json).unwrap())
        .unwrap();
    files
}

#[test]
fn a_capture_in_memory_packs_with_features_pausing_as_it_goes() {
    let opts = PackOptions {
        import: ImportOptions {
            max_size: Some(8),
            ..Default::default()
        },
        features: Some(BaselineFeatures {
            stride: 2,
            autoencoder_steps: 30,
        }),
    };
    let mut events = Vec::new();
    let mut pauses = CountPauses::default();
    let packed = run_to_end(pack_files(Rc::new(capture(3)), &opts, |p| events.push(p), &mut pauses)).unwrap();
    assert_eq!(packed.layout, Layout::Transforms);
    // A pause per frame imported, per frame's features, per autoencoder step, and before writing.
    assert_eq!(pauses.0, 3 + 3 + 30 + 1);
    assert!(events.contains(&PackProgress::Importing { done: 3, total: 3 }));
    assert!(events.contains(&PackProgress::Features(BakeProgress::Extracting { done: 3, total: 3 })));
    assert_eq!(events.last(), Some(&PackProgress::Writing));
    let scene = read_archive(&packed.archive, "packed").unwrap();
    assert_eq!((scene.width, scene.height, scene.frames.len()), (8, 6, 3));
    let codes = scene.features.unwrap();
    assert_eq!((codes.width, codes.height), (4, 3));
    assert_eq!(scene.provenance.source, "cap");
    assert!(
        packed
            .features
            .unwrap()
            .starts_with("features: 30 -> 64 dims on a 4 x 3 grid")
    );
}

#[test]
fn a_folder_of_no_known_layout_gets_the_command_lines_error() {
    let mut files = MemoryFiles::new();
    files.add("holiday/photo.jpg", vec![1, 2, 3]).unwrap();
    let opts = PackOptions {
        import: ImportOptions::default(),
        features: None,
    };
    let err = run_to_end(pack_files(Rc::new(files), &opts, |_| {}, &mut CountPauses::default()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.starts_with("holiday: not a capture layout scribblefield knows; expected one of: an autolabel"),
        "{err}"
    );
}

#[test]
fn a_bad_file_is_named_as_on_the_command_line() {
    let mut broken = MemoryFiles::new();
    broken.add("cap/transforms.json", b"{\"frames\": 3}".to_vec()).unwrap();
    let opts = PackOptions {
        import: ImportOptions::default(),
        features: None,
    };
    let err = run_to_end(pack_files(Rc::new(broken), &opts, |_| {}, &mut CountPauses::default()))
        .err()
        .unwrap()
        .to_string();
    assert!(err.starts_with("cap/transforms.json: "), "{err}");
}

#[test]
fn a_survey_counts_each_layouts_colour_images() {
    let colmap = [
        ("cap/images/b.JPG", 100),
        ("cap/images/a.JPG", 100),
        ("cap/masks/a.JPG.png", 10),
        ("cap/sparse/0/images.txt", 5),
        ("cap/database.db", 1000),
    ];
    let s = survey_capture(colmap);
    assert_eq!(
        (s.images, s.first_image, s.capture_bytes, s.model_bytes),
        (2, Some(1), 215, 5)
    );
    assert_eq!((s.found_in.as_str(), s.dense_depth), ("images/", false));
    let scannet = [
        ("s/color/0.jpg", 1),
        ("s/depth/0.png", 1),
        ("s/color/1.jpg", 1),
        ("s/depth/1.png", 1),
        ("s/pose/0.txt", 1),
    ];
    let s = survey_capture(scannet);
    assert_eq!((s.images, s.found_in.as_str(), s.dense_depth), (2, "color/", true));
    let arkit = [
        ("a/lowres_wide/v_1.000.png", 1),
        ("a/lowres_depth/v_1.000.png", 1),
        ("a/confidence/v_1.000.png", 1),
        ("a/lowres_wide_intrinsics/v_1.000.pincam", 1),
        ("a/lowres_wide.traj", 1),
        ("a/mesh.ply", 1),
    ];
    let s = survey_capture(arkit);
    assert_eq!(
        (s.images, s.found_in.as_str(), s.dense_depth, s.model_bytes),
        (1, "lowres_wide/", true, 2)
    );
    let seven = [("f/frame-000000.color.png", 1), ("f/frame-000000.depth.png", 1)];
    assert_eq!(survey_capture(seven).images, 1);
    let lego = [
        ("lego/transforms_train.json", 1),
        ("lego/train/r_0.png", 1),
        ("lego/test/r_0.png", 1),
        ("lego/test/r_0_depth_0000.png", 1),
        ("lego/test/r_0_normal_0000.png", 1),
    ];
    let s = survey_capture(lego);
    assert_eq!((s.images, s.found_in.as_str()), (2, "the folder"));
    assert_eq!(survey_capture([("x/notes.md", 3)]).images, 0);
    let stray = [
        ("71de12f9/rgb.mp4", 100),
        ("71de12f9/odometry.csv", 3),
        ("71de12f9/camera_matrix.csv", 1),
        ("71de12f9/imu.csv", 5),
        ("71de12f9/depth/000000.png", 2),
        ("71de12f9/depth/000001.png", 2),
        ("71de12f9/confidence/000000.png", 1),
        ("71de12f9/confidence/000001.png", 1),
    ];
    let s = survey_capture(stray);
    assert_eq!(
        (s.images, s.first_image, s.video, s.found_in.as_str(), s.dense_depth),
        (2, None, Some(0), "rgb.mp4", true)
    );
    assert_eq!((s.capture_bytes, s.model_bytes), (115, 109));
    // A video beside no poses is not a capture's colour.
    assert_eq!(survey_capture([("x/rgb.mp4", 1), ("x/a.png", 1)]).video, None);
}

#[test]
fn the_estimate_follows_the_settings() {
    let survey = CaptureSurvey {
        images: 52,
        first_image: Some(0),
        video: None,
        capture_bytes: 9_000_000,
        model_bytes: 4_000_000,
        found_in: "images/".into(),
        dense_depth: false,
    };
    let mut opts = PackOptions {
        import: ImportOptions {
            max_size: Some(96),
            every: 9,
            ..Default::default()
        },
        features: Some(BaselineFeatures {
            stride: 4,
            autoencoder_steps: 100,
        }),
    };
    let a = estimate_pack(&survey, (800, 600), &opts);
    assert_eq!((a.frames, a.size, a.grid), (6, (96, 72), Some((24, 18))));
    // Larger frames: more bytes, memory and time; fewer frames: less.
    opts.import.max_size = Some(320);
    let b = estimate_pack(&survey, (800, 600), &opts);
    assert_eq!(b.size, (320, 240));
    assert!(b.archive_bytes > 5 * a.archive_bytes && b.memory_bytes > a.memory_bytes);
    assert!(b.seconds.total() > a.seconds.total());
    opts.import.max_frames = Some(2);
    assert_eq!(estimate_pack(&survey, (800, 600), &opts).frames, 2);
    // Never upscaled; no features: no grid, no autoencoder.
    opts.import.max_size = Some(2000);
    opts.features = None;
    let c = estimate_pack(&survey, (800, 600), &opts);
    assert_eq!((c.size, c.grid, c.seconds.autoencoder), ((800, 600), None, 0.0));
    // The autoencoder's time grows with its steps.
    let steps = |n| {
        let mut o = opts.clone();
        o.features = Some(BaselineFeatures {
            stride: 8,
            autoencoder_steps: n,
        });
        estimate_pack(&survey, (800, 600), &o).seconds.autoencoder
    };
    assert!(steps(3000) > 2.0 * steps(1000));
}

#[test]
fn the_form_reads_the_settings_and_names_bad_ones() {
    let base = PackOptions {
        import: ImportOptions {
            max_size: Some(640),
            ..Default::default()
        },
        features: Some(BaselineFeatures {
            stride: 8,
            autoencoder_steps: 1000,
        }),
    };
    let mut form = PackForm::from_options(&base);
    assert_eq!(
        (form.max_size.as_str(), form.every.as_str(), form.max_frames.as_str()),
        ("640", "1", "")
    );
    assert_eq!(form.options(&base).unwrap(), base);
    form.max_size = " 120 ".into();
    form.max_frames = "5".into();
    form.features = false;
    let o = form.options(&base).unwrap();
    assert_eq!(
        (o.import.max_size, o.import.max_frames, o.features),
        (Some(120), Some(5), None)
    );
    form.max_size = "4".into();
    form.every = "0".into();
    form.max_frames = "x".into();
    form.features = true;
    form.stride = "".into();
    form.steps = "100001".into();
    let errors = form.options(&base).unwrap_err();
    let fields: Vec<_> = errors.iter().map(|e| e.field).collect();
    assert_eq!(fields, ["max_size", "every", "max_frames", "stride", "steps"]);
    assert_eq!(errors[0].message, "\"4\" is not a longest side from 8 to 8192 pixels");
    assert_eq!(errors[3].message, "give a cell of 1 to 64 pixels");
    // Without features their fields are not looked at.
    form = PackForm::from_options(&base);
    form.features = false;
    form.stride = "x".into();
    assert!(form.options(&base).is_ok());
}
