//! A tiny synthetic COLMAP capture for the importer tests: cameras on an orbit around a grid of
//! 3D points, photos rendered through the lens model (a dark pattern with a white dot where a
//! marker point projects), foreground masks of a disc around the centre, and the model written
//! in COLMAP's text or binary format from one description, so the two can be compared.
#![allow(dead_code)]
use std::path::Path;

use glam::{DMat3, DQuat, DVec2, DVec3};
use image::{GrayImage, Luma, Rgb, RgbImage};

pub const W: u32 = 96;
pub const H: u32 = 72;
pub const PHOTOS: usize = 5;
/// Where (in each camera's own coordinates) the point lies that each photo shows as a white dot:
/// far enough off-centre that the lens moves it by pixels.
pub const MARKER_CAM: DVec3 = DVec3::new(1.125, 0.75, 2.5);
pub const DOT_RADIUS: f64 = 2.5;

#[derive(Clone, Debug)]
pub struct Camera {
    pub id: u32,
    pub model: &'static str,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

impl Camera {
    /// (fx, fy, cx, cy, k1, k2, p1, p2) of the supported models.
    pub fn lens(&self) -> [f64; 8] {
        let p = &self.params;
        match self.model {
            "SIMPLE_PINHOLE" => [p[0], p[0], p[1], p[2], 0.0, 0.0, 0.0, 0.0],
            "PINHOLE" => [p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0, 0.0],
            "SIMPLE_RADIAL" => [p[0], p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0],
            "RADIAL" => [p[0], p[0], p[1], p[2], p[3], p[4], 0.0, 0.0],
            "OPENCV" => [p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]],
            m => panic!("fixture has no lens for {m}"),
        }
    }

    /// COLMAP pixel of a camera-space point, through the lens.
    pub fn project(&self, c: DVec3) -> DVec2 {
        let [fx, fy, cx, cy, k1, k2, p1, p2] = self.lens();
        let (x, y) = (c.x / c.z, c.y / c.z);
        let r2 = x * x + y * y;
        let radial = k1 * r2 + k2 * r2 * r2;
        let xd = x + x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y + y * radial + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * y * y);
        DVec2::new(fx * xd + cx, fy * yd + cy)
    }

    /// COLMAP pixel of a camera-space point through the same camera without distortion.
    pub fn project_pinhole(&self, c: DVec3) -> DVec2 {
        let [fx, fy, cx, cy, ..] = self.lens();
        DVec2::new(fx * c.x / c.z + cx, fy * c.y / c.z + cy)
    }
}

#[derive(Clone, Debug)]
pub struct Image {
    pub id: u32,
    /// World-to-camera (COLMAP's convention).
    pub rotation: DMat3,
    pub translation: DVec3,
    pub camera_id: u32,
    pub name: String,
    pub keypoints: Vec<(DVec2, i64)>,
}

impl Image {
    pub fn to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    pub fn centre(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation)
    }

    fn quaternion(&self) -> [f64; 4] {
        let q = DQuat::from_mat3(&self.rotation);
        [q.w, q.x, q.y, q.z]
    }
}

#[derive(Clone, Debug)]
pub struct Point {
    pub id: u64,
    pub xyz: DVec3,
    pub error: f64,
    pub track: Vec<(u32, u32)>,
}

#[derive(Clone, Debug)]
pub struct Synth {
    pub cameras: Vec<Camera>,
    pub images: Vec<Image>,
    pub points: Vec<Point>,
}

pub fn eye(i: usize) -> DVec3 {
    let a = i as f64 * std::f64::consts::TAU / PHOTOS as f64 + 0.3;
    DVec3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.6)
}

/// World-to-camera rotation of a camera at `eye` looking at the origin, OpenCV axes, world +z up.
fn look_at_origin(eye: DVec3) -> DMat3 {
    let z = (-eye).normalize();
    let x = DVec3::NEG_Z.cross(z).normalize();
    let y = z.cross(x);
    DMat3::from_cols(x, y, z).transpose()
}

/// The grid of 3D points.
pub fn grid_points() -> Vec<DVec3> {
    let mut out = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                out.push(DVec3::new(i as f64 - 1.0, j as f64 - 1.0, k as f64 - 1.0) * 0.5);
            }
        }
    }
    out
}

impl Synth {
    /// One camera of `model` with `params`, PHOTOS images (ids 10, 12, ...), every grid point
    /// observed by every photo it projects into.
    pub fn new(model: &'static str, params: Vec<f64>) -> Synth {
        let cameras = vec![Camera {
            id: 1,
            model,
            width: W,
            height: H,
            params,
        }];
        let mut images: Vec<Image> = (0..PHOTOS)
            .map(|i| {
                let rotation = look_at_origin(eye(i));
                Image {
                    id: 10 + 2 * i as u32,
                    rotation,
                    translation: -(rotation * eye(i)),
                    camera_id: 1,
                    name: format!("photo_{i:02}.png"),
                    keypoints: vec![(DVec2::new(1.0, 1.0), -1)],
                }
            })
            .collect();
        let mut points = Vec::new();
        for (n, xyz) in grid_points().into_iter().enumerate() {
            let id = 3 * n as u64 + 1;
            let mut track = Vec::new();
            for image in images.iter_mut() {
                let px = cameras[0].project(image.to_camera(xyz));
                if px.x > 0.0 && px.y > 0.0 && px.x < W as f64 && px.y < H as f64 {
                    track.push((image.id, image.keypoints.len() as u32));
                    image.keypoints.push((px, id as i64));
                }
            }
            points.push(Point {
                id,
                xyz,
                error: 0.5,
                track,
            });
        }
        Synth {
            cameras,
            images,
            points,
        }
    }

    pub fn camera(&self) -> &Camera {
        &self.cameras[0]
    }

    /// Adds a point seen by the given images (as a keypoint at its projection).
    pub fn add_point(&mut self, id: u64, xyz: DVec3, seen_by: &[usize]) {
        let cam = self.cameras[0].clone();
        let mut track = Vec::new();
        for &i in seen_by {
            let image = &mut self.images[i];
            track.push((image.id, image.keypoints.len() as u32));
            image.keypoints.push((cam.project(image.to_camera(xyz)), id as i64));
        }
        self.points.push(Point {
            id,
            xyz,
            error: 0.5,
            track,
        });
    }

    /// Photos (and masks, a disc around the origin's projection) rendered through the lens.
    pub fn write_photos(&self, dir: &Path, masks: bool) {
        for image in &self.images {
            let cam = self.cameras.iter().find(|c| c.id == image.camera_id).unwrap();
            let dot = cam.project(MARKER_CAM);
            let centre = cam.project(image.to_camera(DVec3::ZERO));
            let photo = RgbImage::from_fn(cam.width, cam.height, |x, y| {
                let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                // Anti-aliased dot: brightness falls off over one pixel at the rim.
                let cover = (DOT_RADIUS + 0.5 - (p - dot).length()).clamp(0.0, 1.0);
                let base = [(x * 2) as f64, 40.0, (y * 2) as f64];
                Rgb(base.map(|b| (b + (255.0 - b) * cover).round() as u8))
            });
            let path = dir.join("images").join(&image.name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            photo.save(&path).unwrap();
            if masks {
                let mask = GrayImage::from_fn(cam.width, cam.height, |x, y| {
                    let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                    Luma([if (p - centre).length() < 15.0 { 255 } else { 0 }])
                });
                let path = dir.join("masks").join(Path::new(&image.name).with_extension("png"));
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                mask.save(&path).unwrap();
            }
        }
    }

    pub fn write_text(&self, dir: &Path) {
        std::fs::create_dir_all(dir).unwrap();
        let mut cams = String::from("# Camera list with one line of data per camera:\n");
        for c in &self.cameras {
            let params: Vec<String> = c.params.iter().map(|p| format!("{p:?}")).collect();
            cams += &format!("{} {} {} {} {}\n", c.id, c.model, c.width, c.height, params.join(" "));
        }
        std::fs::write(dir.join("cameras.txt"), cams).unwrap();
        let mut imgs = String::from("# Image list with two lines of data per image:\n");
        for i in &self.images {
            let [qw, qx, qy, qz] = i.quaternion();
            let t = i.translation;
            imgs += &format!(
                "{} {qw:?} {qx:?} {qy:?} {qz:?} {:?} {:?} {:?} {} {}\n",
                i.id, t.x, t.y, t.z, i.camera_id, i.name
            );
            let kps: Vec<String> = i
                .keypoints
                .iter()
                .map(|(p, id)| format!("{:?} {:?} {id}", p.x, p.y))
                .collect();
            imgs += &format!("{}\n", kps.join(" "));
        }
        std::fs::write(dir.join("images.txt"), imgs).unwrap();
        let mut pts = String::from("# 3D point list with one line of data per point:\n");
        for p in &self.points {
            let track: Vec<String> = p.track.iter().map(|(i, k)| format!("{i} {k}")).collect();
            pts += &format!(
                "{} {:?} {:?} {:?} 128 128 128 {:?} {}\n",
                p.id,
                p.xyz.x,
                p.xyz.y,
                p.xyz.z,
                p.error,
                track.join(" ")
            );
        }
        std::fs::write(dir.join("points3D.txt"), pts).unwrap();
    }

    pub fn write_binary(&self, dir: &Path) {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("cameras.bin"), self.cameras_bin()).unwrap();
        std::fs::write(dir.join("images.bin"), self.images_bin()).unwrap();
        std::fs::write(dir.join("points3D.bin"), self.points_bin()).unwrap();
    }

    pub fn cameras_bin(&self) -> Vec<u8> {
        let mut b = (self.cameras.len() as u64).to_le_bytes().to_vec();
        for c in &self.cameras {
            let model_id: u32 = match c.model {
                "SIMPLE_PINHOLE" => 0,
                "PINHOLE" => 1,
                "SIMPLE_RADIAL" => 2,
                "RADIAL" => 3,
                "OPENCV" => 4,
                "OPENCV_FISHEYE" => 5,
                m => panic!("no id for {m}"),
            };
            b.extend(c.id.to_le_bytes());
            b.extend(model_id.to_le_bytes());
            b.extend((c.width as u64).to_le_bytes());
            b.extend((c.height as u64).to_le_bytes());
            c.params.iter().for_each(|p| b.extend(p.to_le_bytes()));
        }
        b
    }

    pub fn images_bin(&self) -> Vec<u8> {
        let mut b = (self.images.len() as u64).to_le_bytes().to_vec();
        for i in &self.images {
            b.extend(i.id.to_le_bytes());
            i.quaternion().iter().for_each(|v| b.extend(v.to_le_bytes()));
            i.translation.to_array().iter().for_each(|v| b.extend(v.to_le_bytes()));
            b.extend(i.camera_id.to_le_bytes());
            b.extend(i.name.as_bytes());
            b.push(0);
            b.extend((i.keypoints.len() as u64).to_le_bytes());
            for (p, id) in &i.keypoints {
                b.extend(p.x.to_le_bytes());
                b.extend(p.y.to_le_bytes());
                b.extend(id.to_le_bytes());
            }
        }
        b
    }

    pub fn points_bin(&self) -> Vec<u8> {
        let mut b = (self.points.len() as u64).to_le_bytes().to_vec();
        for p in &self.points {
            b.extend(p.id.to_le_bytes());
            p.xyz.to_array().iter().for_each(|v| b.extend(v.to_le_bytes()));
            b.extend([128u8, 128, 128]);
            b.extend(p.error.to_le_bytes());
            b.extend((p.track.len() as u64).to_le_bytes());
            for (i, k) in &p.track {
                b.extend(i.to_le_bytes());
                b.extend(k.to_le_bytes());
            }
        }
        b
    }
}
