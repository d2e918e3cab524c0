//! COLMAP's text model: `cameras.txt`, `images.txt` (two lines per image: the pose line, then the
//! keypoints line, which may be empty) and `points3D.txt`; `#` starts a comment line.
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::str::FromStr;

use glam::{DVec2, DVec3};

use super::model::{
    At, Camera, Image, MAX_POINTS, Model, Point3D, camera, duplicate, param_count, rotation, too_many_points,
};
use super::read_model_file;
use crate::scene::error::{Result, SceneError};

pub(super) fn read(dir: &Path) -> Result<Model> {
    let paths = super::FILES.map(|f| dir.join(format!("{f}.txt")));
    let files = paths.clone().map(|p| p.display().to_string());
    let texts = [0, 1, 2].map(|i| text_of(&paths[i], &files[i]));
    let [cameras, images, points] = texts;
    parse([&cameras?, &images?, &points?], files)
}

/// The model from the texts of cameras.txt, images.txt and points3D.txt, named by `files`.
pub(super) fn parse(texts: [&str; 3], files: [String; 3]) -> Result<Model> {
    Ok(Model {
        cameras: read_cameras(texts[0], &files[0])?,
        images: read_images(texts[1], &files[1])?,
        points: read_points(texts[2], &files[2])?,
        files,
    })
}

fn text_of(path: &Path, file: &str) -> Result<String> {
    String::from_utf8(read_model_file(path)?).map_err(|e| {
        SceneError::invalid(
            file,
            format!("not a text file (not UTF-8 at byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

/// Data lines with their 1-based line numbers: blank lines and comments skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// The whitespace-separated fields of one line, read in order; errors name file, line and field.
struct Fields<'a> {
    file: &'a str,
    at: At,
    words: std::str::SplitWhitespace<'a>,
}

impl<'a> Fields<'a> {
    fn new(file: &'a str, line: usize, text: &'a str) -> Self {
        Fields {
            file,
            at: At::Line(line),
            words: text.split_whitespace(),
        }
    }

    fn err(&self, problem: String) -> SceneError {
        SceneError::invalid(self.file, format!("{}: {problem}", self.at))
    }

    fn word(&mut self, field: &str) -> Result<&'a str> {
        self.words
            .next()
            .ok_or_else(|| self.err(format!("the line ends before {field}")))
    }

    fn parse<T: FromStr>(&mut self, field: &str, kind: &str) -> Result<T> {
        let word = self.word(field)?;
        word.parse()
            .map_err(|_| self.err(format!("{field}: cannot read {word:?} as {kind}")))
    }

    fn id<T: FromStr>(&mut self, field: &str) -> Result<T> {
        self.parse(field, "an id (a whole number >= 0)")
    }

    fn real(&mut self, field: &str) -> Result<f64> {
        let v: f64 = self.parse(field, "a number")?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(format!("{field} is {v}, not a finite number")))
        }
    }

    /// Consecutive numbers named `fields`.
    fn reals<const N: usize>(&mut self, fields: [&str; N]) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for (v, field) in out.iter_mut().zip(fields) {
            *v = self.real(field)?;
        }
        Ok(out)
    }

    fn rest(self) -> Vec<&'a str> {
        self.words.collect()
    }

    fn remaining(&self) -> usize {
        self.words.clone().count()
    }
}

fn read_cameras(text: &str, file: &str) -> Result<BTreeMap<u32, Camera>> {
    let mut cameras = BTreeMap::new();
    for (line, l) in data_lines(text) {
        let mut f = Fields::new(file, line, l);
        let id: u32 = f.id("CAMERA_ID")?;
        let model = f.word("MODEL")?;
        let width = f.parse("WIDTH", "a size in pixels")?;
        let height = f.parse("HEIGHT", "a size in pixels")?;
        let at = f.at;
        let count = param_count(model, id, file, at)?;
        let mut params = Vec::with_capacity(count);
        for i in 0..count {
            params.push(f.real(&format!("PARAMS[{i}] of {model}"))?);
        }
        let extra = f.remaining();
        if extra > 0 {
            return Err(SceneError::invalid(
                file,
                format!(
                    "{at}: camera {id}: {model} takes {count} parameters, found {}",
                    count + extra
                ),
            ));
        }
        let cam = camera(model, id, (width, height), &params, file, at)?;
        if cameras.insert(id, cam).is_some() {
            return Err(duplicate("camera", id, file, at));
        }
    }
    Ok(cameras)
}

fn read_images(text: &str, file: &str) -> Result<Vec<Image>> {
    let mut images = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((line, l)) = lines.next() {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut f = Fields::new(file, line, l);
        let id: u32 = f.id("IMAGE_ID")?;
        let q = f.reals(["QW", "QX", "QY", "QZ"])?;
        let t = f.reals(["TX", "TY", "TZ"])?;
        let camera_id: u32 = f.id("CAMERA_ID")?;
        let at = f.at;
        let name = f.rest().join(" ");
        if name.is_empty() {
            return Err(SceneError::invalid(
                file,
                format!("{at}: image {id}: the line ends before NAME"),
            ));
        }
        // The keypoints line always follows its image line, even when it is empty.
        let (kp_line, kp) = lines.next().unwrap_or((line + 1, ""));
        let points2d = read_keypoints(kp, file, kp_line, id)?;
        images.push(Image {
            id,
            rotation: rotation(q, file, at, id)?,
            translation: DVec3::from_array(t),
            camera_id,
            name,
            points2d,
            at,
        });
    }
    Ok(images)
}

fn read_keypoints(text: &str, file: &str, line: usize, image: u32) -> Result<Vec<(DVec2, Option<u64>)>> {
    let mut f = Fields::new(file, line, text);
    let words = f.remaining();
    if !words.is_multiple_of(3) {
        return Err(f.err(format!(
            "image {image}: POINTS2D must be triples (X Y POINT3D_ID), found {words} numbers"
        )));
    }
    let mut out = Vec::with_capacity(words / 3);
    for i in 0..words / 3 {
        let x = f.real(&format!("POINTS2D[{i}] X"))?;
        let y = f.real(&format!("POINTS2D[{i}] Y"))?;
        let field = format!("POINTS2D[{i}] POINT3D_ID");
        let id: i64 = f.parse(&field, "a 3D point id (or -1)")?;
        let point = match id {
            -1 => None,
            id if id >= 0 => Some(id as u64),
            _ => return Err(f.err(format!("{field} is {id}; expected a 3D point id or -1"))),
        };
        out.push((DVec2::new(x, y), point));
    }
    Ok(out)
}

fn read_points(text: &str, file: &str) -> Result<HashMap<u64, Point3D>> {
    let mut points = HashMap::new();
    for (line, l) in data_lines(text) {
        let mut f = Fields::new(file, line, l);
        let id: u64 = f.id("POINT3D_ID")?;
        let xyz = f.reals(["X", "Y", "Z"])?;
        for name in ["R", "G", "B"] {
            f.parse::<u8>(name, "a colour value (0-255)")?;
        }
        let error = f.real("ERROR")?;
        let at = f.at;
        let words = f.remaining();
        if !words.is_multiple_of(2) {
            return Err(SceneError::invalid(
                file,
                format!("{at}: point {id}: TRACK must be pairs (IMAGE_ID POINT2D_IDX), found {words} numbers"),
            ));
        }
        let mut pairs = Vec::with_capacity(words / 2);
        for i in 0..words / 2 {
            pairs.push((
                f.id(&format!("TRACK[{i}] IMAGE_ID"))?,
                f.id(&format!("TRACK[{i}] POINT2D_IDX"))?,
            ));
        }
        let point = Point3D {
            xyz: DVec3::from_array(xyz),
            error,
            track: pairs,
            at,
        };
        if points.insert(id, point).is_some() {
            return Err(duplicate("3D point", id, file, at));
        }
        if points.len() > MAX_POINTS {
            return Err(too_many_points(points.len(), file));
        }
    }
    Ok(points)
}
