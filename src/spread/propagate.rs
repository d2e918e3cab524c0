//! Scribble propagation inside each annotated frame: a random walker (Grady 2006) on the frame's
//! pixel grid turns a few strokes into confident pseudo-labels over most of the frame, and the
//! field trains on those as well as on the strokes (docs/quality.md explains why and what it
//! measured).
//!
//! The field's semantic head sees only what the rendered features carry; scribbles cover a few
//! percent of a frame, and on a real capture several objects share their colour (three red
//! objects in the YCB clip), so a head trained on strokes alone generalizes by colour and paints
//! one red object with another's class. The image itself knows better where each object ends:
//! a random walk from each unlabelled pixel, whose steps prefer neighbours of similar colour and
//! depth, reaches the strokes of its own object first. Its probabilities are the solution of one
//! sparse linear system per class (the graph Laplacian restricted to unlabelled pixels); only
//! pixels whose most likely class wins by a clear margin become labels, so a weak edge that the
//! walk crosses gives an uncertain pixel, not a wrong label.
//!
//! A frame with strokes of a single class is left as drawn: with one class the walk is certain
//! everywhere, and a user who marks one object on a frame has not said that the rest of the frame
//! is that object.

use crate::pause::{NoPause, Pause, run_to_end};
use crate::scene::Guide;
use crate::spread::margin;
use crate::spread::normals::depth_normals;
use crate::spread::options::{PropagationOptions, UndrawnFrames};
use crate::spread::pixel_walk::PixelGraph;
use crate::spread::point_walk::{PointLabeller, PointWalkOptions};
use crate::spread::support_plane::largest_plane;
use crate::spread::view_seeds::{View, region_class};
use std::collections::HashMap;

use crate::labels::{LabelSet, UNLABELLED, rasterize_frame};
use crate::scene::{Intrinsics, Scene};

/// On a capture with sparse depth, the probability and the lead over the next class at which a
/// drawn frame's walk labels a pixel whose points then seed the walk across views.
const SEED_CERTAINTY: f32 = 0.7;

/// Gaps between a reconstruction's points in a photo, as a share of the diagonal, that still
/// belong to the footprint of their class (`spread::margin::erode_footprints`).
const FOOTPRINT_GAP: f32 = 0.007;

/// The label map a frame trains on: the strokes, plus (when `options` are enabled and the strokes
/// hold at least two classes) the pixels the walk assigns with confidence. Class ids at or above
/// `classes` are dropped (the model has no logit for them). `strokes` is the frame's rasterized
/// strokes (`labels::rasterize_frame`) at the guide's size; `camera` (the frame's intrinsics)
/// lets the walk use surface normals (`PropagationOptions::normal_sigma`).
pub fn propagate_frame(
    strokes: &[u16],
    classes: usize,
    guide: Guide<'_>,
    camera: Option<&Intrinsics>,
    options: &PropagationOptions,
) -> Vec<u16> {
    run_to_end(walk_frame(strokes, classes, guide, camera, options, &mut NoPause))
}

/// [`propagate_frame`], pausing between iterations of its walks.
pub(crate) async fn walk_frame(
    strokes: &[u16],
    classes: usize,
    guide: Guide<'_>,
    camera: Option<&Intrinsics>,
    options: &PropagationOptions,
    pause: &mut impl Pause,
) -> Vec<u16> {
    let mut seeds: Vec<u16> = strokes
        .iter()
        .map(|&c| if (c as usize) < classes { c } else { UNLABELLED })
        .collect();
    let present: Vec<u16> = (0..classes as u16).filter(|c| seeds.contains(c)).collect();
    if !options.enabled || present.len() < 2 || seeds.len() != pixel_count(guide) {
        return seeds;
    }
    let guarded = options.guarded_walks.guards(guide.depth.is_some(), present.len());
    let options = &PropagationOptions {
        feature_sigma: if guarded { options.feature_sigma } else { 0.0 },
        edge_margin: if guarded { options.edge_margin } else { 0.0 },
        ..*options
    };
    let graph = PixelGraph::new(guide, camera, options);
    let mut probabilities: Vec<Vec<f32>> = Vec::with_capacity(present.len());
    for &class in &present {
        probabilities.push(graph.walk(&seeds, class, pause).await);
    }
    for (pixel, label) in seeds.iter_mut().enumerate() {
        if *label != UNLABELLED {
            continue;
        }
        let (mut best, mut first, mut second) = (0, f32::MIN, f32::MIN);
        for (k, p) in probabilities.iter().enumerate() {
            let p = p[pixel];
            if p > first {
                second = first;
                first = p;
                best = k;
            } else if p > second {
                second = p;
            }
        }
        if first >= options.min_probability && first - second >= options.min_margin {
            *label = present[best];
        }
    }
    let (width, height) = (guide.rgb.width() as usize, guide.rgb.height() as usize);
    let radius = (options.edge_margin * (width as f32).hypot(height as f32)).round() as usize;
    if radius > 0 {
        let walked_from: Vec<u16> = strokes
            .iter()
            .map(|&c| if (c as usize) < classes { c } else { UNLABELLED })
            .collect();
        margin::erode_walked(&mut seeds, &walked_from, width, height, radius);
    }
    seeds
}

/// Every annotated frame's training label map (see [`propagate_frame`]), by frame index, for the
/// frames of `scene` that `labels` annotates.
pub fn propagate_labels(
    scene: &Scene,
    labels: &LabelSet,
    classes: usize,
    options: &PropagationOptions,
) -> Vec<(u32, Vec<u16>)> {
    PropagationCache::default().maps(scene, labels, classes, options)
}

/// Keeps each frame's propagated map until that frame's seeds change, so an edit on one frame
/// (the page sends the whole label set after every stroke) walks that frame alone; on a capture
/// with sparse depth the points' neighbour graph is built once, the walk over it reruns on every
/// edit, and only frames whose strokes changed walk again.
#[derive(Default)]
pub struct PropagationCache {
    settings: Option<(usize, PropagationOptions)>,
    /// Per frame: the seeds it walked from and the map that gave.
    frames: HashMap<u32, (Vec<u16>, Vec<u16>)>,
    /// The scene's points, their graph and where they land in each frame, once a capture with
    /// sparse depth needs them.
    sparse: Option<SparseCapture>,
    /// Per drawn frame of such a capture: its strokes and their walk inside the frame alone,
    /// which seeds the walk over the points.
    drawn: HashMap<u32, (Vec<u16>, Vec<u16>)>,
    /// Per drawn frame with dense depth, its support plane (`None`: no plane found).
    planes: HashMap<u32, Option<Vec<bool>>>,
    /// The class the last maps gave the pixels far from every point ([`PropagationCache::far_class`]).
    far_class: Option<u16>,
    /// Per drawn frame, what the self-check's fold that leaves each class out found there
    /// (`spread::check`), and for which strokes, classes and options.
    pub(crate) left_out: HashMap<u32, LeftOutMemo>,
}

/// One frame's result of the self-check's class-left-out fold: pixels of the held-back strokes
/// and those another class claimed (`None`: fewer than three classes on the frame).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LeftOutMemo {
    pub strokes: Vec<u16>,
    pub classes: usize,
    pub options: PropagationOptions,
    pub held_claimed: Option<(u64, u64)>,
}

impl PropagationCache {
    /// As [`propagate_labels`], reusing the maps of frames whose seeds are unchanged.
    pub fn maps(
        &mut self,
        scene: &Scene,
        labels: &LabelSet,
        classes: usize,
        options: &PropagationOptions,
    ) -> Vec<(u32, Vec<u16>)> {
        run_to_end(self.maps_pausing(scene, labels, classes, options, &mut NoPause))
    }

    /// [`PropagationCache::maps`], pausing between iterations of its walks (`pause`).
    pub async fn maps_pausing(
        &mut self,
        scene: &Scene,
        labels: &LabelSet,
        classes: usize,
        options: &PropagationOptions,
        pause: &mut impl Pause,
    ) -> Vec<(u32, Vec<u16>)> {
        if self.settings != Some((classes, *options)) {
            self.frames.clear();
            self.drawn.clear();
            self.planes.clear();
            self.settings = Some((classes, *options));
        }
        self.far_class = None;
        let seeds = frame_seeds(scene, labels, classes, options, self, pause).await;
        self.frames.retain(|frame, _| seeds.iter().any(|s| s.frame == *frame));
        let mut maps = Vec::with_capacity(seeds.len());
        for FrameSeeds {
            frame,
            strokes,
            carried,
        } in seeds
        {
            let walked = match &carried {
                // Far pixels gave the frame a second class: the projected points and the far
                // pixels walk together, under the strokes.
                Some(Carried::Walks(carried)) => {
                    let mut start = carried.clone();
                    for (s, &d) in start.iter_mut().zip(strokes.iter().flatten()) {
                        if d != UNLABELLED {
                            *s = d;
                        }
                    }
                    Some(start)
                }
                _ => strokes.clone(),
            };
            let plane = match &strokes {
                Some(drawn) if options.support_plane => self.support_plane_labels(scene, frame, drawn, classes),
                _ => None,
            };
            let walked = match (walked, Guide::of_frame(scene, frame as usize)) {
                (Some(start), Some(guide)) => Some(match self.frames.get(&frame).filter(|(seen, _)| *seen == start) {
                    Some((_, map)) => map.clone(),
                    None => {
                        let map = walk_frame(&start, classes, guide, Some(&scene.intrinsics), options, pause).await;
                        self.frames.insert(frame, (start, map.clone()));
                        map
                    }
                }),
                (start, _) => start,
            };
            // What the walk leaves unlabelled on the frame's support plane takes the plane's
            // class: the walk fades before it covers a floor, and seeding the walk with the
            // plane instead took labels from the objects' edges (docs/quality.md).
            let walked = match (walked, plane) {
                (Some(mut map), Some(plane)) => {
                    for (m, p) in map.iter_mut().zip(plane) {
                        if *m == UNLABELLED {
                            *m = p;
                        }
                    }
                    Some(map)
                }
                (walked, _) => walked,
            };
            // Next to the object's points the far pixels' class came through the walk alone,
            // across edges too faint to stop it: the field decides those pixels.
            let walked = match (walked, &carried, self.sparse.as_ref().and_then(|s| s.regions.as_ref())) {
                (Some(mut map), Some(Carried::Walks(_)), Some(regions)) => {
                    regions.keep_far_class_off_points(&mut map, strokes.as_deref(), frame as usize);
                    Some(map)
                }
                (walked, _, _) => walked,
            };
            // Only what the user drew or what reaches two classes walks. The points of a frame
            // may all be one object's, and a walk from those alone would paint the whole frame
            // with it; where they have a label it is more often right than the walk's, so it
            // replaces the walk's (never a stroke).
            let map = match (walked, carried) {
                (Some(mut map), Some(Carried::AsIs(carried))) => {
                    let drawn = strokes.as_deref().unwrap_or_default();
                    for ((m, c), &d) in map.iter_mut().zip(carried).zip(drawn) {
                        if c != UNLABELLED && d == UNLABELLED {
                            *m = c;
                        }
                    }
                    map
                }
                (None, Some(Carried::AsIs(mut map))) => {
                    let (width, height) = (scene.width as usize, scene.height as usize);
                    let diagonal = (width as f32).hypot(height as f32);
                    let margin_px = (options.undrawn_margin * diagonal).round() as usize;
                    let gap = ((FOOTPRINT_GAP * diagonal).round() as usize).max(1);
                    // The far pixels' class is labelled only far from every point already
                    // (`view_seeds::FAR_FROM_POINTS`): only the points' own labels keep a margin.
                    margin::erode_footprints(&mut map, width, height, gap, margin_px, self.far_class);
                    map
                }
                (Some(map), _) => map,
                (None, _) => continue,
            };
            maps.push((frame, map));
        }
        maps
    }

    /// The class the last [`PropagationCache::maps`] gave the pixels far from every point of a
    /// capture with sparse depth: what the strokes say lies beyond the reconstruction (a photo
    /// capture's room, `view_seeds::region_class`). `None` on captures with dense depth or none,
    /// with propagation off, or when the strokes on such pixels name no single class.
    pub fn far_class(&self) -> Option<u16> {
        self.far_class
    }

    /// The class the strokes on a drawn frame's support plane agree on, over the plane's pixels
    /// (`UNLABELLED` elsewhere; `PropagationOptions::support_plane`). `None` when the frame has
    /// no dense depth, no plane, strokes of one class, or strokes that disagree on the plane.
    fn support_plane_labels(&mut self, scene: &Scene, frame: u32, drawn: &[u16], classes: usize) -> Option<Vec<u16>> {
        let mut present = drawn.iter().filter(|&&c| (c as usize) < classes);
        let first = *present.next()?;
        if present.all(|&c| c == first) {
            return None;
        }
        let plane = self
            .planes
            .entry(frame)
            .or_insert_with(|| support_plane_of(scene, frame as usize))
            .as_deref()?;
        let class = region_class(&[(drawn, plane)], classes)?;
        Some(plane.iter().map(|&on| if on { class } else { UNLABELLED }).collect())
    }
}

/// The largest plane in frame `frame`'s depth, when the depth is dense (`spread::support_plane`).
fn support_plane_of(scene: &Scene, frame: usize) -> Option<Vec<bool>> {
    let depth = scene.frames.get(frame)?.depth.as_ref()?;
    let readings = depth.pixels().filter(|d| d.0[0] > 0).count();
    if readings * 2 <= depth.len() || depth.dimensions() != (scene.width, scene.height) {
        return None;
    }
    let normals = depth_normals(depth, &scene.intrinsics);
    largest_plane(depth, &scene.intrinsics, &normals)
}

/// What labels across views need of a capture with sparse depth, built once per scene: the
/// readings as points with their neighbour graph, each frame's view of the points, and each
/// frame's pixels far from every point.
struct SparseCapture {
    labeller: PointLabeller,
    views: Vec<View>,
    far: Vec<Vec<bool>>,
    /// The last walk over the points: the classes and seed maps it started from, and each
    /// point's class (the page asks again after every edit, most of which leave the seeds as
    /// they were).
    last: Option<LastPointWalk>,
    /// Where the points of the classes other than the far pixels' lie in each frame, for the
    /// far class and points' classes they were found for.
    regions: Option<PointRegions>,
}

/// Per frame, the pixels the points not of the far pixels' class mark.
struct PointRegions {
    far_class: u16,
    point_classes: Vec<u16>,
    /// Inside their outline (`View::outline_of_points_not_in`).
    outline: Vec<Vec<bool>>,
    /// Near one of them (`View::near_points_not_in`).
    near: Vec<Vec<bool>>,
}

impl PointRegions {
    /// Unlabels the far class in `map` (frame `frame`'s walk) near the other classes' points,
    /// except where the user drew it.
    fn keep_far_class_off_points(&self, map: &mut [u16], strokes: Option<&[u16]>, frame: usize) {
        let Some(near) = self.near.get(frame) else { return };
        for (i, (m, &near)) in map.iter_mut().zip(near).enumerate() {
            let drawn = strokes.and_then(|s| s.get(i)).is_some_and(|&d| d != UNLABELLED);
            if near && *m == self.far_class && !drawn {
                *m = UNLABELLED;
            }
        }
    }
}

/// Per frame (by index), a label map.
type FrameMaps = Vec<(u32, Vec<u16>)>;

/// The classes, far pixels' class and seed maps a walk over the points started from, and each
/// point's class.
type LastPointWalk = (usize, Option<u16>, FrameMaps, Vec<u16>);

impl SparseCapture {
    async fn new(scene: &Scene, pause: &mut impl Pause) -> SparseCapture {
        let labeller = PointLabeller::new(scene, &PointWalkOptions::default());
        let mut views = Vec::with_capacity(scene.frames.len());
        let mut far = Vec::with_capacity(scene.frames.len());
        for f in 0..scene.frames.len() {
            pause.pause().await;
            let view = View::of_frame(scene, f, labeller.positions());
            far.push(view.far_from_points());
            views.push(view);
        }
        SparseCapture {
            labeller,
            views,
            far,
            last: None,
            regions: None,
        }
    }

    /// Finds where each frame's points not of class `class` lie, unless it is known for these
    /// points' classes.
    async fn find_regions(&mut self, point_classes: &[u16], class: u16, pause: &mut impl Pause) {
        if matches!(&self.regions, Some(r) if r.far_class == class && r.point_classes == point_classes) {
            return;
        }
        let mut outline = Vec::with_capacity(self.views.len());
        let mut near = Vec::with_capacity(self.views.len());
        for view in &self.views {
            pause.pause().await;
            outline.push(view.outline_of_points_not_in(point_classes, class));
            near.push(view.near_points_not_in(point_classes, class));
        }
        self.regions = Some(PointRegions {
            far_class: class,
            point_classes: point_classes.to_vec(),
            outline,
            near,
        });
    }

    /// Each point's class from the walk over the points seeded by `walked`
    /// (`PointLabeller::point_classes_pausing`).
    async fn point_classes(
        &mut self,
        walked: FrameMaps,
        classes: usize,
        far_class: Option<u16>,
        pause: &mut impl Pause,
    ) -> &[u16] {
        let stale =
            !matches!(&self.last, Some((c, far, seen, _)) if *c == classes && *far == far_class && *seen == walked);
        if stale {
            let point_classes = self
                .labeller
                .point_classes_pausing(&walked, classes, far_class, pause)
                .await;
            self.last = Some((classes, far_class, walked, point_classes));
        }
        self.last.as_ref().map_or(&[], |(_, _, _, p)| p.as_slice())
    }
}

/// A frame's labels before its own walk.
struct FrameSeeds {
    frame: u32,
    /// The frame's rasterized strokes, if it has any.
    strokes: Option<Vec<u16>>,
    /// Labels the points carried to it, if any.
    carried: Option<Carried>,
}

/// Labels the points carry to a frame.
enum Carried {
    /// Its own readings' labels, trained on as they are.
    AsIs(Vec<u16>),
    /// The labels of every point that lands in it, and its pixels far from every point in the
    /// class the strokes give such pixels (`spread::view_seeds`): a start for its own walk (a
    /// drawn frame's; a frame nobody drew on walks only with `UndrawnFrames::Walk`).
    Walks(Vec<u16>),
}

/// What each frame starts from: its rasterized strokes, and on a capture with sparse depth
/// (when `across_views`) the labels the points carry to it. Frames in ascending order.
async fn frame_seeds(
    scene: &Scene,
    labels: &LabelSet,
    classes: usize,
    options: &PropagationOptions,
    cache: &mut PropagationCache,
    pause: &mut impl Pause,
) -> Vec<FrameSeeds> {
    let mut frames: Vec<u32> = labels
        .frames
        .iter()
        .map(|f| f.frame)
        .filter(|f| (*f as usize) < scene.frames.len())
        .collect();
    frames.sort_unstable();
    frames.dedup();
    let mut seeds: Vec<FrameSeeds> = frames
        .into_iter()
        .map(|frame| FrameSeeds {
            frame,
            strokes: Some(rasterize_frame(labels.frame(frame), scene.width, scene.height)),
            carried: None,
        })
        .collect();
    if !(options.enabled && options.across_views && scene.has_sparse_depth()) {
        return seeds;
    }
    let strokes: Vec<(u32, Vec<u16>)> = seeds
        .iter()
        .filter_map(|s| s.strokes.clone().map(|m| (s.frame, m)))
        .collect();
    // The points walk from what each drawn frame's own walk labels, not from the strokes alone:
    // strokes on the room behind an object cover no point (the reconstruction missed the room),
    // and the walk inside the frame carries the object's other class to the points it has.
    // A wrong seed reaches every photo, so the walk that seeds is stricter than the one a frame
    // trains on.
    let seeding = PropagationOptions {
        min_probability: options.min_probability.max(SEED_CERTAINTY),
        min_margin: options.min_margin.max(SEED_CERTAINTY),
        ..*options
    };
    cache.drawn.retain(|frame, _| strokes.iter().any(|(f, _)| f == frame));
    let mut walked: Vec<(u32, Vec<u16>)> = Vec::with_capacity(strokes.len());
    for (frame, drawn) in &strokes {
        let map = match cache.drawn.get(frame).filter(|(seen, _)| seen == drawn) {
            Some((_, map)) => map.clone(),
            None => {
                let map = match Guide::of_frame(scene, *frame as usize) {
                    Some(guide) => walk_frame(drawn, classes, guide, Some(&scene.intrinsics), &seeding, pause).await,
                    None => drawn.clone(),
                };
                cache.drawn.insert(*frame, (drawn.clone(), map.clone()));
                map
            }
        };
        walked.push((*frame, map));
    }
    let sparse = match cache.sparse.take() {
        Some(sparse) => sparse,
        None => SparseCapture::new(scene, pause).await,
    };
    let sparse = cache.sparse.insert(sparse);
    let drawn: Vec<(&[u16], &[bool])> = strokes
        .iter()
        .map(|(f, map)| (map.as_slice(), sparse.far[*f as usize].as_slice()))
        .collect();
    let unreconstructed = region_class(&drawn, classes);
    cache.far_class = unreconstructed;
    let point_classes = sparse
        .point_classes(walked, classes, unreconstructed, pause)
        .await
        .to_vec();
    if let Some(class) = unreconstructed {
        sparse.find_regions(&point_classes, class, pause).await;
    }
    let (views, far) = (&sparse.views, &sparse.far);
    for (f, view) in views.iter().enumerate() {
        let mut carried = view.labels(&point_classes);
        let carried = match unreconstructed {
            Some(class) => {
                // A far pixel inside the outline of the other classes' points is more likely a
                // hole in the object's reconstruction than the room: it is left to the walk.
                let outline = sparse.regions.as_ref().map_or(&[][..], |r| r.outline[f].as_slice());
                for (i, (c, &far)) in carried.iter_mut().zip(&far[f]).enumerate() {
                    let inside = outline.get(i).copied().unwrap_or(false);
                    if far && !inside && *c == UNLABELLED {
                        *c = class;
                    }
                }
                Carried::Walks(carried)
            }
            None => {
                // Without a class for the far pixels, a frame keeps only its own readings'
                // labels: another frame's point landing on it may be hidden behind its surface.
                Carried::AsIs(own_reading_labels(scene, f, carried))
            }
        };
        if carried_is_empty(&carried) {
            continue;
        }
        match seeds.iter_mut().find(|s| s.frame == f as u32) {
            Some(own) => own.carried = Some(carried),
            None => {
                let carried = match (options.undrawn_frames, carried) {
                    (UndrawnFrames::Points, Carried::Walks(map)) => Carried::AsIs(map),
                    (_, carried) => carried,
                };
                seeds.push(FrameSeeds {
                    frame: f as u32,
                    strokes: None,
                    carried: Some(carried),
                })
            }
        }
    }
    seeds.sort_by_key(|s| s.frame);
    seeds
}

/// `carried` kept at the frame's own depth readings only.
fn own_reading_labels(scene: &Scene, frame: usize, mut carried: Vec<u16>) -> Vec<u16> {
    match &scene.frames[frame].depth {
        Some(depth) => {
            for (c, d) in carried.iter_mut().zip(depth.pixels()) {
                if d.0[0] == 0 {
                    *c = UNLABELLED;
                }
            }
        }
        None => carried.fill(UNLABELLED),
    }
    carried
}

fn carried_is_empty(carried: &Carried) -> bool {
    match carried {
        Carried::AsIs(map) | Carried::Walks(map) => map.iter().all(|&c| c == UNLABELLED),
    }
}

fn pixel_count(guide: Guide<'_>) -> usize {
    guide.rgb.width() as usize * guide.rgb.height() as usize
}

#[cfg(test)]
#[path = "propagate_tests.rs"]
mod tests;
