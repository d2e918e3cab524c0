//! Every broken input names its file, the line or record, and the field.
use super::*;

/// A text capture whose `file` (in sparse/0) has `from` replaced by `to` (once; it must occur).
fn text_edited(file: &str, from: &str, to: &str) -> TempDir {
    let tmp = capture(&pinhole(), Format::Text, false);
    let path = tmp.path().join("sparse/0").join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{from:?} not in {file}");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    tmp
}

/// The line of `file` that starts with `prefix`.
fn line_of(tmp: &TempDir, file: &str, prefix: &str) -> String {
    let text = std::fs::read_to_string(tmp.path().join("sparse/0").join(file)).unwrap();
    text.lines().find(|l| l.starts_with(prefix)).unwrap().to_string()
}

/// `line` with its `index`-th space-separated word replaced.
fn with_word(line: &str, index: usize, word: &str) -> String {
    let mut words: Vec<&str> = line.split(' ').collect();
    words[index] = word;
    words.join(" ")
}

#[test]
fn missing_model_files_are_named() {
    for file in ["cameras.txt", "images.txt", "points3D.txt"] {
        let tmp = capture(&pinhole(), Format::Text, false);
        std::fs::remove_file(tmp.path().join("sparse/0").join(file)).unwrap();
        if file == "cameras.txt" {
            // Without cameras there is no model folder to find.
            assert!(detect_layout(tmp.path()).is_err());
            continue;
        }
        expect_err(run(tmp.path()), &[file, "missing", "COLMAP model"]);
    }
    let tmp = capture(&pinhole(), Format::Binary, false);
    std::fs::remove_file(tmp.path().join("sparse/0/points3D.bin")).unwrap();
    expect_err(run(tmp.path()), &["points3D.bin", "missing"]);
}

#[test]
fn bad_text_fields_name_line_and_field() {
    let tmp = capture(&pinhole(), Format::Text, false);
    let camera = line_of(&tmp, "cameras.txt", "1 ");
    let image = line_of(&tmp, "images.txt", "12 ");
    let point = line_of(&tmp, "points3D.txt", "4 ");
    let check = |file: &str, to: String, needles: &[&str]| {
        let from = match file {
            "cameras.txt" => &camera,
            "images.txt" => &image,
            _ => &point,
        };
        let tmp = text_edited(file, from, &to);
        expect_err(run(tmp.path()), &[needles, &[file]].concat());
    };
    let cameras = "cameras.txt";
    check(
        cameras,
        camera.replace(" 96 ", " wide "),
        &["line 2", "WIDTH", "\"wide\""],
    );
    check(
        cameras,
        format!("{camera} 0.1"),
        &["line 2", "camera 1", "PINHOLE takes 4 parameters, found 5"],
    );
    check(
        cameras,
        camera.replace("PINHOLE", "OPENCV_FISHEYE"),
        &["camera 1", "OPENCV_FISHEYE", "not supported"],
    );
    check(
        cameras,
        camera.replace("PINHOLE", "WEIRD"),
        &["camera 1", "unknown model \"WEIRD\""],
    );
    check(
        cameras,
        camera.replace(" 82.0 ", " -82.0 "),
        &["camera 1", "focal length"],
    );
    let images = "images.txt";
    check(images, with_word(&image, 1, "nan"), &["line 4", "QW", "NaN"]);
    check(
        images,
        with_word(&image, 1, "2.0"),
        &["line 4", "image 12", "quaternion", "norm"],
    );
    check(images, with_word(&image, 6, "1e999"), &["line 4", "TY", "inf"]);
    check(
        images,
        image.replace(" 1 photo_01", " 9 photo_01"),
        &["line 4", "image 12", "camera 9"],
    );
    check(images, image.replace(" 1 photo_01.png", " 1"), &["line 4", "NAME"]);
    check(images, image.replace("12 ", "10 "), &["line 4", "image id 10", "twice"]);
    let points = "points3D.txt";
    check(
        points,
        point.replace(" 128 128 128 ", " 128 300 128 "),
        &["line 3", "G", "\"300\""],
    );
    check(
        points,
        format!("{point} 10"),
        &["line 3", "point 4", "TRACK must be pairs"],
    );
    check(points, format!("{point} 99 0"), &["line 3", "point 4", "image 99"]);
    check(
        points,
        format!("{point} 10 500"),
        &["point 4", "keypoint 500 of image 10"],
    );
    check(points, format!("{point}\n{point}"), &["3D point id 4", "twice"]);
}

#[test]
fn bad_keypoints_are_named() {
    let tmp = capture(&pinhole(), Format::Text, false);
    let text = std::fs::read_to_string(tmp.path().join("sparse/0/images.txt")).unwrap();
    let keypoints = text.lines().nth(2).unwrap().to_string();
    // Line 3 is image 10's keypoints: a number short of a triple, then a point that is not there.
    let short = text_edited("images.txt", &keypoints, keypoints.rsplit_once(' ').unwrap().0);
    expect_err(run(short.path()), &["images.txt", "line 3", "image 10", "triples"]);
    let ghost = text_edited("images.txt", &keypoints, &format!("{keypoints} 5.0 5.0 777"));
    expect_err(run(ghost.path()), &["images.txt", "line 2", "image 10", "3D point 777"]);
    let negative = text_edited("images.txt", &keypoints, &format!("{keypoints} 5.0 5.0 -7"));
    expect_err(run(negative.path()), &["images.txt", "line 3", "POINT3D_ID", "-7"]);
}

/// A binary capture whose `file` is replaced by `bytes`.
fn binary_with(file: &str, bytes: Vec<u8>) -> TempDir {
    let tmp = capture(&pinhole(), Format::Binary, false);
    std::fs::write(tmp.path().join("sparse/0").join(file), bytes).unwrap();
    tmp
}

#[test]
fn bad_binary_models_name_record_and_field() {
    let synth = pinhole();
    let images = synth.images_bin();
    let tmp = binary_with("images.bin", images[..images.len() - 5].to_vec());
    expect_err(run(tmp.path()), &["images.bin", "record 5", "truncated"]);
    let tmp = binary_with("images.bin", images[..30].to_vec());
    expect_err(run(tmp.path()), &["images.bin", "truncated or wrong count", "5 images"]);
    let mut extra = images.clone();
    extra.extend([0; 7]);
    let tmp = binary_with("images.bin", extra);
    expect_err(
        run(tmp.path()),
        &["images.bin", "wrong count", "7 bytes follow the 5 images"],
    );
    let mut huge = images.clone();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let tmp = binary_with("images.bin", huge);
    expect_err(run(tmp.path()), &["images.bin", "wrong count"]);
    // QW of the first image is NaN.
    let mut nan = images.clone();
    nan[12..20].copy_from_slice(&f64::NAN.to_le_bytes());
    let tmp = binary_with("images.bin", nan);
    expect_err(run(tmp.path()), &["images.bin", "record 1", "image 10: QW", "NaN"]);

    let mut fisheye = synth.clone();
    fisheye.cameras[0].model = "OPENCV_FISHEYE";
    fisheye.cameras[0].params = vec![80.0, 80.0, 48.0, 36.0, 0.1, 0.0, 0.0, 0.0];
    let tmp = binary_with("cameras.bin", fisheye.cameras_bin());
    expect_err(
        run(tmp.path()),
        &["cameras.bin", "record 1", "camera 1", "OPENCV_FISHEYE", "not supported"],
    );
    let mut unknown = synth.cameras_bin();
    unknown[12..16].copy_from_slice(&99u32.to_le_bytes());
    let tmp = binary_with("cameras.bin", unknown);
    expect_err(run(tmp.path()), &["cameras.bin", "camera 1", "unknown model id 99"]);

    let points = synth.points_bin();
    let tmp = binary_with("points3D.bin", points[..points.len() - 3].to_vec());
    expect_err(run(tmp.path()), &["points3D.bin", "truncated"]);
    let mut ghost = synth.clone();
    ghost.points[0].track.push((55, 0));
    let tmp = binary_with("points3D.bin", ghost.points_bin());
    expect_err(run(tmp.path()), &["points3D.bin", "record 1", "point 1", "image 55"]);
}

#[test]
fn photos_must_match_their_camera() {
    let tmp = capture(&pinhole(), Format::Text, false);
    save_rgb(&tmp.path().join("images/photo_00.png"), &pattern_rgb(W + 4, H, 0));
    expect_err(run(tmp.path()), &["photo_00.png", "photo is 100x72", "96x72"]);

    let mut synth = pinhole();
    synth.cameras.push(Camera {
        id: 2,
        model: "SIMPLE_PINHOLE",
        width: 2 * W,
        height: 2 * H,
        params: vec![160.0, 96.0, 72.0],
    });
    synth.images[3].camera_id = 2;
    let tmp = capture(&synth, Format::Text, false);
    expect_err(
        run(tmp.path()),
        &["cameras.txt", "camera 2 (192x144", "photo_03.png", "differ in size"],
    );

    let mut none = pinhole();
    for image in &mut none.images {
        image.name = format!("gone/{}", image.name);
    }
    let tmp = tempfile::tempdir().unwrap();
    pinhole().write_photos(tmp.path(), false);
    none.write_text(&tmp.path().join("sparse/0"));
    expect_err(run(tmp.path()), &["images", "none of the 5 photos"]);
}

#[test]
fn image_names_outside_images_are_refused() {
    // Refused whether or not the named file exists.
    let tmp = text_edited("images.txt", "photo_01.png", "../../secret.png");
    expect_err(
        run(tmp.path()),
        &[
            "images.txt",
            "image 12 name \"../../secret.png\" climbs out with ..",
            "outside the capture folder",
        ],
    );

    let tmp = text_edited("images.txt", "photo_01.png", "/etc/passwd");
    expect_err(
        run(tmp.path()),
        &["image 12 name \"/etc/passwd\" is absolute", "--allow-outside-paths"],
    );

    // A name that stays inside is fine.
    let tmp = text_edited("images.txt", "photo_01.png", "./photo_01.png");
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.scene.frames.len(), 5);

    // Allowed on request: the escaping photo is packed.
    let tmp = text_edited("images.txt", "photo_01.png", "../images/photo_01.png");
    let opts = ImportOptions {
        allow_outside_paths: true,
        ..Default::default()
    };
    assert_eq!(run_with(tmp.path(), &opts).unwrap().scene.frames.len(), 5);
    expect_err(run(tmp.path()), &["climbs out with .."]);
}
