//! Labels carried between views through a reconstruction's points (docs/quality.md).
//!
//! A photo capture without a depth sensor has depth only where its structure-from-motion model
//! put a 3D point (the COLMAP importer stores each image's tracks as sparse depth). On such a
//! capture the walk inside one frame has little to go on (soft edges, one colour for an object
//! and the wall behind it), and the field learns geometry slowly, so strokes on two frames say
//! little about the other fifty. The points know more: every reading of every frame is a point
//! in the world, the same 3D point seen from several frames lands in one place, and an object is
//! a cluster of points apart from the wall behind it. A random walk over the points' nearest
//! neighbours, started from the readings under the strokes, labels the points of every frame;
//! each frame then trains on (and walks from) the labels of its own readings.
use glam::DVec3;

use super::colour::srgb_to_lab;
use super::pixel_walk::conjugate_gradient;
use super::sparse_solve::Factored;
use crate::labels::UNLABELLED;
use crate::pause::{NoPause, Pause, run_to_end};
use crate::scene::Scene;

/// Neighbours each point links to (the graph is made symmetric, so some have more).
const NEIGHBOURS: usize = 10;
/// Points per occupied cell the neighbour search aims at.
const POINTS_PER_CELL: f64 = 4.0;
/// How much each step of the walk fades when the strokes' points hold a single class (see
/// [`PointLabeller::point_classes_pausing`]): a walk of about ten million steps, which crosses any
/// surface the reconstruction joins but hardly ever a link of [`MIN_WEIGHT`], or a jump across
/// a colour edge between clusters (docs/results/quality-log.md, "one class under the strokes").
const LONE_CLASS_FADE: f64 = 1e-7;
/// Smallest edge weight: keeps the graph connected so each system has one solution.
const MIN_WEIGHT: f64 = 1e-9;

/// How the points carry labels. Distances are in units of the median distance between a point
/// and its nearest neighbours, so the setting does not depend on the model's scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointWalkOptions {
    /// Distance at which an edge's weight falls to e^-1.
    pub distance_sigma: f64,
    /// CIE L*a*b* difference at which an edge's weight falls to e^-1.
    pub colour_sigma: f64,
    /// A point takes a label where its most likely class leads the next by this much.
    pub min_margin: f64,
}

impl Default for PointWalkOptions {
    fn default() -> Self {
        PointWalkOptions {
            distance_sigma: 1.0,
            colour_sigma: 20.0,
            min_margin: 0.2,
        }
    }
}

/// Every depth reading of a scene as a world point.
struct Points {
    xyz: Vec<DVec3>,
    lab: Vec<[f32; 3]>,
    /// (frame, pixel index) of each reading.
    at: Vec<(u32, u32)>,
}

impl Points {
    fn of_scene(scene: &Scene) -> Points {
        let mut points = Points {
            xyz: Vec::new(),
            lab: Vec::new(),
            at: Vec::new(),
        };
        let width = scene.width as usize;
        for (f, frame) in scene.frames.iter().enumerate() {
            let Some(depth) = &frame.depth else { continue };
            for (i, (d, rgb)) in depth.pixels().zip(frame.rgb.pixels()).enumerate() {
                if d.0[0] == 0 {
                    continue;
                }
                let z = f64::from(d.0[0]) * scene.depth_scale;
                let (u, v) = ((i % width) as f64, (i / width) as f64);
                let camera = scene.intrinsics.ray_dir(u, v) * z;
                points.xyz.push(frame.pose.transform_point(camera));
                points.lab.push(srgb_to_lab(rgb.0));
                points.at.push((f as u32, i as u32));
            }
        }
        points
    }
}

/// The symmetric nearest-neighbour graph, as an adjacency list with weights.
struct PointGraph {
    edges: Vec<Vec<(u32, f64)>>,
}

impl PointGraph {
    fn new(points: &Points, options: &PointWalkOptions) -> PointGraph {
        let near = nearest_neighbours(&points.xyz, NEIGHBOURS);
        let mut distances: Vec<f64> = near.iter().flatten().map(|(_, d)| *d).collect();
        let scale = median(&mut distances).max(1e-12);
        let mut edges: Vec<Vec<(u32, f64)>> = vec![Vec::new(); points.xyz.len()];
        for (i, list) in near.iter().enumerate() {
            for &(j, d) in list {
                let dc: f32 = (0..3)
                    .map(|k| (points.lab[i][k] - points.lab[j as usize][k]).powi(2))
                    .sum();
                let w = (-(d / (options.distance_sigma * scale)).powi(2)
                    - f64::from(dc) / options.colour_sigma.powi(2))
                .exp()
                .max(MIN_WEIGHT);
                edges[i].push((j, w));
                edges[j as usize].push((i as u32, w));
            }
        }
        // An edge found from both ends is one edge: merge the duplicates.
        for list in &mut edges {
            list.sort_by_key(|(j, _)| *j);
            list.dedup_by_key(|(j, _)| *j);
        }
        PointGraph { edges }
    }

    /// For each class of `classes`, the probability that a walk from each point reaches a seed
    /// of that class before a seed of another (seeds fixed at 1 or 0; see `propagate`'s walk,
    /// here fading only where `fade` asks for it). The system is the same for every class (only
    /// its right-hand side differs), so it is factored once and solved exactly; should the
    /// factorization fail, conjugate gradients solve it as they did before.
    ///
    /// With `fade` above 0, each step also ends the walk with probability about
    /// `fade / (1 + fade)`, so a point's probabilities sum to less than 1 the more steps its
    /// seeds lie away: with one class, that is how far the class reaches.
    async fn walk(&self, seeds: &[u16], classes: &[u16], fade: f64, pause: &mut impl Pause) -> Vec<Vec<f64>> {
        let n = seeds.len();
        let free: Vec<usize> = (0..n).filter(|&i| seeds[i] == UNLABELLED).collect();
        let mut slot = vec![u32::MAX; n];
        for (k, &i) in free.iter().enumerate() {
            slot[i] = k as u32;
        }
        // The system over the free points in one flat list (each free point's free neighbours,
        // by slot), so each iteration reads memory in order.
        let mut degree = vec![0f64; free.len()];
        let mut rhs = vec![vec![0f64; free.len()]; classes.len()];
        let mut starts = Vec::with_capacity(free.len() + 1);
        let mut links: Vec<(u32, f64)> = Vec::new();
        for (k, &i) in free.iter().enumerate() {
            starts.push(links.len());
            for &(j, w) in &self.edges[i] {
                degree[k] += w;
                if let Some(c) = classes.iter().position(|&c| c == seeds[j as usize]) {
                    rhs[c][k] += w;
                }
                if slot[j as usize] != u32::MAX {
                    links.push((slot[j as usize], w));
                }
            }
        }
        starts.push(links.len());
        for d in &mut degree {
            *d *= 1.0 + fade;
        }
        pause.pause().await;
        let negated: Vec<(u32, f64)> = links.iter().map(|&(j, w)| (j, -w)).collect();
        let factored = Factored::new(&degree, &starts, &negated);
        let mut out = Vec::with_capacity(classes.len());
        for (rhs, &class) in rhs.iter().zip(classes) {
            pause.pause().await;
            let x = match &factored {
                Ok(factored) => factored.solve(rhs),
                Err(_) => {
                    let apply = |x: &[f64], out: &mut [f64]| {
                        for (k, out) in out.iter_mut().enumerate() {
                            let mut sum = degree[k] * x[k];
                            for &(j, w) in &links[starts[k]..starts[k + 1]] {
                                sum -= w * x[j as usize];
                            }
                            *out = sum;
                        }
                    };
                    conjugate_gradient(apply, rhs, &degree, 2000, pause).await
                }
            };
            let mut p: Vec<f64> = seeds.iter().map(|&s| if s == class { 1.0 } else { 0.0 }).collect();
            for (k, &i) in free.iter().enumerate() {
                p[i] = x[k].clamp(0.0, 1.0);
            }
            out.push(p);
        }
        out
    }
}

/// A scene's readings as points and their neighbour graph: built once per scene (the
/// expensive part), then asked for labels after every edit.
pub struct PointLabeller {
    points: Points,
    graph: PointGraph,
    width: u32,
    height: u32,
    frames: usize,
    min_margin: f64,
}

impl PointLabeller {
    pub fn new(scene: &Scene, options: &PointWalkOptions) -> PointLabeller {
        let points = Points::of_scene(scene);
        let graph = PointGraph::new(&points, options);
        PointLabeller {
            points,
            graph,
            width: scene.width,
            height: scene.height,
            frames: scene.frames.len(),
            min_margin: options.min_margin,
        }
    }

    /// Label maps for every frame with readings: each reading takes the class the walk over the
    /// points gives it from the readings under `strokes` (per annotated frame, its rasterized
    /// strokes at the scene's size), where that class clearly wins. Frames whose readings get
    /// no label are left out. Nothing is labelled unless the strokes cover readings of at least
    /// two classes.
    pub fn label(&self, strokes: &[(u32, Vec<u16>)], classes: usize) -> Vec<(u32, Vec<u16>)> {
        let classes_of_points = self.point_classes(strokes, classes);
        let pixels = (self.width * self.height) as usize;
        let mut maps: Vec<Option<Vec<u16>>> = vec![None; self.frames];
        for (&class, &(frame, pixel)) in classes_of_points.iter().zip(&self.points.at) {
            if class != UNLABELLED {
                let map = maps[frame as usize].get_or_insert_with(|| vec![UNLABELLED; pixels]);
                map[pixel as usize] = class;
            }
        }
        maps.into_iter()
            .enumerate()
            .filter_map(|(f, m)| m.map(|m| (f as u32, m)))
            .collect()
    }

    /// Every point's class as [`PointLabeller::label`] finds it (`UNLABELLED` where no class
    /// clearly wins, and everywhere unless the strokes cover points of two classes), in the
    /// order of [`PointLabeller::positions`].
    pub fn point_classes(&self, strokes: &[(u32, Vec<u16>)], classes: usize) -> Vec<u16> {
        run_to_end(self.point_classes_pausing(strokes, classes, None, &mut NoPause))
    }

    /// [`PointLabeller::point_classes`], pausing between iterations of its walks. `far_class`
    /// is the class the strokes give what the reconstruction missed (`view_seeds::region_class`),
    /// if they give it one: when the points under the strokes then hold a single other class,
    /// that class is the reconstruction's and the far pixels are the rest. The points take it
    /// where a walk that fades reaches them clearly ([`LONE_CLASS_FADE`]), not everywhere.
    pub async fn point_classes_pausing(
        &self,
        strokes: &[(u32, Vec<u16>)],
        classes: usize,
        far_class: Option<u16>,
        pause: &mut impl Pause,
    ) -> Vec<u16> {
        let seeds: Vec<u16> = self
            .points
            .at
            .iter()
            .map(|&(f, i)| {
                strokes
                    .iter()
                    .find(|(frame, _)| *frame == f)
                    .and_then(|(_, map)| map.get(i as usize).copied())
                    .filter(|&c| (c as usize) < classes)
                    .unwrap_or(UNLABELLED)
            })
            .collect();
        let present: Vec<u16> = (0..classes as u16).filter(|c| seeds.contains(c)).collect();
        match (present.as_slice(), far_class) {
            ([_, _, ..], _) => {}
            (&[lone], Some(far)) if far != lone => {
                let reached = self.graph.walk(&seeds, &present, LONE_CLASS_FADE, pause).await;
                // The walk's other outcome, fading out, is the competing class.
                return reached[0]
                    .iter()
                    .map(|&p| {
                        if p - (1.0 - p) >= self.min_margin {
                            lone
                        } else {
                            UNLABELLED
                        }
                    })
                    .collect();
            }
            _ => return vec![UNLABELLED; seeds.len()],
        }
        let probabilities = self.graph.walk(&seeds, &present, 0.0, pause).await;
        (0..seeds.len())
            .map(|p| {
                let (mut best, mut first, mut second) = (0, f64::MIN, f64::MIN);
                for (k, probability) in probabilities.iter().enumerate() {
                    let v = probability[p];
                    if v > first {
                        (second, first, best) = (first, v, k);
                    } else if v > second {
                        second = v;
                    }
                }
                if first - second >= self.min_margin {
                    present[best]
                } else {
                    UNLABELLED
                }
            })
            .collect()
    }

    /// The points in the world, one per depth reading.
    pub fn positions(&self) -> &[DVec3] {
        &self.points.xyz
    }
}

/// [`PointLabeller::label`] for a scene labelled once.
pub fn label_points(
    scene: &Scene,
    strokes: &[(u32, Vec<u16>)],
    classes: usize,
    options: &PointWalkOptions,
) -> Vec<(u32, Vec<u16>)> {
    PointLabeller::new(scene, options).label(strokes, classes)
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// For each point, up to `k` nearest other points with their distances, found through a uniform
/// grid: the 27 cells around a point's own. Points farther than a cell away may be missed where
/// a cell's neighbourhood holds fewer than `k`; the walk needs near neighbours, not exactly k.
fn nearest_neighbours(xyz: &[DVec3], k: usize) -> Vec<Vec<(u32, f64)>> {
    if xyz.len() < 2 {
        return vec![Vec::new(); xyz.len()];
    }
    let (lo, hi) = xyz
        .iter()
        .fold((xyz[0], xyz[0]), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    // Points lie on surfaces: start from the spacing of n points over the box's largest face,
    // then adjust once towards POINTS_PER_CELL points in each occupied cell.
    let extent = (hi - lo).max(DVec3::splat(1e-9));
    let face = (extent.x * extent.y).max(extent.y * extent.z).max(extent.x * extent.z);
    let mut cell = (face / xyz.len() as f64).sqrt() * POINTS_PER_CELL.sqrt();
    for _ in 0..2 {
        let occupied = grid(xyz, lo, cell).len() as f64;
        cell *= (POINTS_PER_CELL * occupied / xyz.len() as f64).sqrt();
    }
    let cells = grid(xyz, lo, cell);
    xyz.iter()
        .enumerate()
        .map(|(i, p)| {
            let c = cell_of(*p, lo, cell);
            let mut near: Vec<(u32, f64)> = Vec::new();
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = cells.get(&(c.0 + dx, c.1 + dy, c.2 + dz)) {
                            near.extend(
                                list.iter()
                                    .filter(|&&j| j as usize != i)
                                    .map(|&j| (j, p.distance(xyz[j as usize]))),
                            );
                        }
                    }
                }
            }
            let keep = k.min(near.len());
            if keep > 0 && keep < near.len() {
                near.select_nth_unstable_by(keep - 1, |a, b| a.1.total_cmp(&b.1));
            }
            near.truncate(keep);
            near
        })
        .collect()
}

type Cell = (i64, i64, i64);

fn cell_of(p: DVec3, lo: DVec3, cell: f64) -> Cell {
    let c = ((p - lo) / cell).floor();
    (c.x as i64, c.y as i64, c.z as i64)
}

fn grid(xyz: &[DVec3], lo: DVec3, cell: f64) -> std::collections::HashMap<Cell, Vec<u32>> {
    let mut cells: std::collections::HashMap<Cell, Vec<u32>> = std::collections::HashMap::new();
    for (i, p) in xyz.iter().enumerate() {
        cells.entry(cell_of(*p, lo, cell)).or_default().push(i as u32);
    }
    cells
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_finds_the_true_nearest_neighbours_of_a_surface() {
        // A 40 x 40 lattice on a tilted plane with a little jitter: the nearest neighbours by
        // brute force and through the grid agree.
        let mut xyz = Vec::new();
        for a in 0..40 {
            for b in 0..40 {
                let jitter = ((a * 7 + b * 13) % 10) as f64 * 0.01;
                xyz.push(DVec3::new(a as f64, b as f64 * 0.8, 0.3 * a as f64 + jitter));
            }
        }
        let near = nearest_neighbours(&xyz, 6);
        for i in [0usize, 41, 820, 1599] {
            let mut brute: Vec<(usize, f64)> = (0..xyz.len())
                .filter(|&j| j != i)
                .map(|j| (j, xyz[i].distance(xyz[j])))
                .collect();
            brute.sort_by(|a, b| a.1.total_cmp(&b.1));
            let mut got: Vec<f64> = near[i].iter().map(|(_, d)| *d).collect();
            got.sort_by(f64::total_cmp);
            let want: Vec<f64> = brute.iter().take(6).map(|(_, d)| *d).collect();
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() < 1e-9, "point {i}: {got:?} against {want:?}");
            }
            assert_eq!(got.len(), 6);
        }
    }

    #[test]
    fn one_seeded_class_follows_its_surface_but_not_the_weakest_links() {
        // A chain of 500 points (a surface's longest walk, and then some) seeded at one end, and
        // a cluster of 100 joined to its other end by one link of the smallest weight. The
        // strokes cover a point of class 1; the far pixels are class 0.
        const CHAIN: usize = 500;
        const CLUSTER: usize = 100;
        let n = CHAIN + CLUSTER;
        let mut edges: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
        for i in 0..n - 1 {
            let w = if i == CHAIN - 1 { MIN_WEIGHT } else { 1.0 };
            edges[i].push((i as u32 + 1, w));
            edges[i + 1].push((i as u32, w));
        }
        let labeller = PointLabeller {
            points: Points {
                xyz: vec![DVec3::ZERO; n],
                lab: vec![[50.0, 0.0, 0.0]; n],
                at: (0..n as u32).map(|i| (0, i)).collect(),
            },
            graph: PointGraph { edges },
            width: n as u32,
            height: 1,
            frames: 1,
            min_margin: PointWalkOptions::default().min_margin,
        };
        let mut strokes = vec![UNLABELLED; n];
        strokes[0] = 1;
        let strokes = [(0, strokes)];
        let classes = |far| run_to_end(labeller.point_classes_pausing(&strokes, 2, far, &mut NoPause));
        let with_far = classes(Some(0));
        assert!(
            with_far[..CHAIN].iter().all(|&c| c == 1),
            "the chain takes the class to its end"
        );
        assert!(
            with_far[CHAIN..].iter().all(|&c| c == UNLABELLED),
            "the weakly joined cluster is left"
        );
        // Without a class for the far pixels, or with the seeds' own, one class says nothing.
        for far in [None, Some(1)] {
            assert!(classes(far).iter().all(|&c| c == UNLABELLED), "far class {far:?}");
        }
    }

    #[test]
    fn two_clusters_take_the_classes_of_their_own_seeds() {
        // Two blobs of points a distance apart, one seed each: every point follows its blob.
        let mut xyz = Vec::new();
        for (centre, n) in [(DVec3::ZERO, 200), (DVec3::new(10.0, 0.0, 0.0), 150)] {
            for i in 0..n {
                let t = i as f64;
                xyz.push(centre + DVec3::new((t * 0.37).sin(), (t * 0.61).cos(), (t * 0.13).sin()));
            }
        }
        let points = Points {
            lab: vec![[50.0, 0.0, 0.0]; xyz.len()],
            at: (0..xyz.len() as u32).map(|i| (0, i)).collect(),
            xyz,
        };
        let graph = PointGraph::new(&points, &PointWalkOptions::default());
        let mut seeds = vec![UNLABELLED; points.xyz.len()];
        seeds[3] = 0;
        seeds[260] = 1;
        let p = run_to_end(graph.walk(&seeds, &[0, 1], 0.0, &mut NoPause));
        assert!(p[1][..200].iter().all(|&v| v < 0.1), "the first blob is class 0");
        assert!(p[1][200..].iter().all(|&v| v > 0.9), "the second blob is class 1");
        for (zero, one) in p[0].iter().zip(&p[1]) {
            assert!(
                (zero + one - 1.0).abs() < 1e-9,
                "a converged walk reaches one class or the other: {zero} + {one}"
            );
        }
    }
}
