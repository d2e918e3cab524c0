//! A labelled point cloud from the frames' depth: each pixel with a depth reading is lifted to
//! the world through the frame's intrinsics and pose and takes its mask's class. Frames see
//! the same surfaces again and again, so points are fused on a grid of 1/512 of the scene
//! bounds' longest side: one point per occupied cell, at the mean of its points, of the class
//! most of them have (the lowest id on a tie), coloured in that class's colour. Written as
//! binary little-endian PLY with `x y z` (float), `red green blue` and `label` (uchar, the
//! class id).
use std::collections::HashMap;

use glam::DVec3;
use image::GrayImage;

use crate::labels::ClassInfo;
use crate::scene::Scene;

pub const FILE: &str = "points.ply";
/// Grid cells along the longest side of the scene's bounds.
const CELLS: f64 = 512.0;

struct Cell {
    sum: DVec3,
    points: u32,
    /// (class, points of that class).
    votes: Vec<(u8, u32)>,
}

/// The fused points, frame by frame.
pub struct PointCloud<'a> {
    scene: &'a Scene,
    cell: f64,
    index: HashMap<[i64; 3], usize>,
    cells: Vec<Cell>,
}

/// One fused point.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub position: [f32; 3],
    pub color: [u8; 3],
    pub label: u8,
}

impl<'a> PointCloud<'a> {
    pub fn new(scene: &'a Scene) -> PointCloud<'a> {
        let b = &scene.bounds;
        let longest = (0..3).map(|i| b.max[i] - b.min[i]).fold(0.0, f64::max);
        // Bounds are checked when an archive is read; a degenerate box still gets a usable grid.
        let cell = if longest.is_finite() && longest > 0.0 {
            longest / CELLS
        } else {
            1e-3
        };
        PointCloud {
            scene,
            cell,
            index: HashMap::new(),
            cells: Vec::new(),
        }
    }

    /// Adds frame `i`'s pixels with depth, each of the class `mask` (of any size: a pixel
    /// takes the mask pixel its centre falls in) gives it.
    pub fn add_frame(&mut self, i: usize, mask: &GrayImage) {
        let scene = self.scene;
        let Some(frame) = scene.frames.get(i) else {
            return;
        };
        let Some(depth) = &frame.depth else {
            return;
        };
        let (w, h) = depth.dimensions();
        let (mw, mh) = mask.dimensions();
        // Depth is stored at the scene's size; the intrinsics are of that size.
        let k = scene.intrinsics.scaled((scene.width, scene.height), (w, h));
        let pose = frame.pose.0;
        for y in 0..h {
            let my = (((y as f64 + 0.5) * mh as f64 / h as f64) as u32).min(mh.saturating_sub(1));
            for x in 0..w {
                let d = depth.get_pixel(x, y).0[0];
                if d == 0 {
                    continue;
                }
                let mx = (((x as f64 + 0.5) * mw as f64 / w as f64) as u32).min(mw.saturating_sub(1));
                let class = mask.get_pixel(mx, my).0[0];
                let camera = k.ray_dir(x as f64, y as f64) * (d as f64 * scene.depth_scale);
                let world = pose.transform_point3(camera);
                if !world.is_finite() {
                    continue;
                }
                self.add(world, class);
            }
        }
    }

    fn add(&mut self, p: DVec3, class: u8) {
        let key = [
            (p.x / self.cell).floor() as i64,
            (p.y / self.cell).floor() as i64,
            (p.z / self.cell).floor() as i64,
        ];
        let next = self.cells.len();
        let at = *self.index.entry(key).or_insert(next);
        if at == next {
            self.cells.push(Cell {
                sum: DVec3::ZERO,
                points: 0,
                votes: Vec::new(),
            });
        }
        let cell = &mut self.cells[at];
        cell.sum += p;
        cell.points += 1;
        match cell.votes.iter_mut().find(|(c, _)| *c == class) {
            Some((_, n)) => *n += 1,
            None => cell.votes.push((class, 1)),
        }
    }

    /// The fused points, in the order their cells were first reached.
    pub fn points(&self, classes: &[ClassInfo]) -> Vec<Point> {
        self.cells
            .iter()
            .map(|c| {
                let (label, _) = c
                    .votes
                    .iter()
                    .copied()
                    .max_by_key(|&(class, n)| (n, std::cmp::Reverse(class)))
                    .unwrap_or((0, 0));
                let mean = c.sum / c.points as f64;
                Point {
                    position: [mean.x as f32, mean.y as f32, mean.z as f32],
                    color: classes.get(label as usize).map_or([0, 0, 0], |k| k.color),
                    label,
                }
            })
            .collect()
    }

    /// The PLY file of the fused points.
    pub fn to_ply(&self, classes: &[ClassInfo]) -> Vec<u8> {
        write_ply(&self.points(classes), classes)
    }
}

/// Binary little-endian PLY of `points`; the header's comments list the classes.
pub fn write_ply(points: &[Point], classes: &[ClassInfo]) -> Vec<u8> {
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header.push_str("comment scribblefield: points from the frames' depth, label = class id\n");
    for (i, c) in classes.iter().enumerate() {
        // A line break in a name would end the comment early and break the header.
        let name: String = c
            .name
            .chars()
            .map(|ch| if ch.is_control() { ' ' } else { ch })
            .collect();
        header.push_str(&format!("comment class {i} {name}\n"));
    }
    header.push_str(&format!(
        "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar label\nend_header\n",
        points.len()
    ));
    let mut out = header.into_bytes();
    out.reserve(points.len() * 16);
    for p in points {
        for v in p.position {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&p.color);
        out.push(p.label);
    }
    out
}

/// Reads back a file [`write_ply`] wrote (`at` names it in errors): the points and the
/// header's class comments.
pub fn read_ply(bytes: &[u8], at: &str) -> Result<Vec<Point>, crate::scene::SceneError> {
    use crate::scene::SceneError;
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .map(|p| p + end.len())
        .ok_or_else(|| SceneError::invalid(at, "no end_header line"))?;
    let header =
        std::str::from_utf8(&bytes[..header_len]).map_err(|_| SceneError::invalid(at, "header is not UTF-8"))?;
    let mut lines = header.lines();
    if lines.next() != Some("ply") || lines.next() != Some("format binary_little_endian 1.0") {
        return Err(SceneError::invalid(at, "not a binary little-endian PLY file"));
    }
    let mut count = None;
    let mut properties = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", "vertex", n] => {
                count = Some(
                    n.parse::<usize>()
                        .map_err(|_| SceneError::invalid(at, format!("vertex count {n:?}")))?,
                )
            }
            ["property", ty, name] => properties.push(format!("{ty} {name}")),
            _ => {}
        }
    }
    let want = [
        "float x",
        "float y",
        "float z",
        "uchar red",
        "uchar green",
        "uchar blue",
        "uchar label",
    ];
    if properties != want {
        return Err(SceneError::invalid(
            at,
            format!("properties {properties:?}, expected {want:?}"),
        ));
    }
    let count = count.ok_or_else(|| SceneError::invalid(at, "no vertex element"))?;
    let body = &bytes[header_len..];
    if body.len() != count * 16 {
        return Err(SceneError::invalid(
            at,
            format!("{} bytes of points, {count} points need {}", body.len(), count * 16),
        ));
    }
    Ok(body
        .chunks_exact(16)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            Point {
                position: [f(0), f(4), f(8)],
                color: [c[12], c[13], c[14]],
                label: c[15],
            }
        })
        .collect())
}
