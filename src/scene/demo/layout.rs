//! What the demo scene contains and where: a room, a wooden table and four textured objects
//! on it, jittered by the seed; plus the queries the renderer and the checks need.
use glam::DVec3;

use super::geometry::{Ray, Shape, SurfaceHit, may_hit_sphere};
use super::textures::{Colour, Texture};
use crate::rng::SplitMix64;
use crate::scene::camera::Bounds;

/// Class names, indexed by the ids stored in the ground truth.
pub const DEMO_CLASSES: &[&str] = &["background", "table", "box", "mug", "ball", "cone"];

/// Display colours of `DEMO_CLASSES`, chosen to be told apart at a glance.
pub const DEMO_CLASS_COLOURS: [[u8; 3]; 6] = [
    [90, 90, 100],
    [170, 110, 50],
    [230, 50, 60],
    [50, 110, 240],
    [250, 210, 40],
    [40, 200, 110],
];

pub const BACKGROUND: u8 = 0;
pub const TABLE: u8 = 1;
const BOX: u8 = 2;
const MUG: u8 = 3;
const BALL: u8 = 4;
const CONE: u8 = 5;

/// The room: floor at z = 0, the table in the middle.
const ROOM_MIN: DVec3 = DVec3::new(-1.8, -1.6, 0.0);
const ROOM_MAX: DVec3 = DVec3::new(1.8, 1.6, 2.4);
/// Table top, centred on the z axis; its upper face is at `TABLE_HEIGHT`.
const TABLE_SIZE: DVec3 = DVec3::new(1.0, 0.7, 0.04);
const TABLE_HEIGHT: f64 = 0.75;
const LEG_SIDE: f64 = 0.05;
const LEG_INSET: f64 = 0.06;
/// A single point light, fixed so shading differs between views only through the geometry.
const LIGHT: DVec3 = DVec3::new(0.8, -1.0, 2.2);
const AMBIENT: f64 = 0.35;
const DIFFUSE: f64 = 0.7;
/// Gap kept between object footprints and to the table edge.
const CLEARANCE: f64 = 0.02;

/// One solid of the scene.
#[derive(Clone, Copy, Debug)]
pub struct Part {
    pub shape: Shape,
    pub texture: Texture,
    pub class: u8,
}

/// The first surface a ray meets.
#[derive(Clone, Copy, Debug)]
pub struct WorldHit {
    /// Ray parameter: the z-depth for camera rays whose camera-space z is 1.
    pub t: f64,
    pub class: u8,
    pub point: DVec3,
    pub normal: DVec3,
    /// Index of the part hit, to find silhouette edges.
    pub part: usize,
    local: DVec3,
}

/// The demo scene's geometry and materials, made from a seed.
#[derive(Clone, Debug)]
pub struct DemoWorld {
    parts: Vec<Part>,
    /// `Shape::bounding_sphere` of each part.
    part_spheres: Vec<Option<(DVec3, f64)>>,
    /// Box around everything but the room: rays that miss it can only hit the room.
    cluster: Shape,
}

/// The colours a seed gives the scene. Some are shared between classes on purpose, so colour
/// alone cannot separate them: the ball has the box's red, the mug has the box's cream.
struct Palette {
    red: Colour,
    cream: Colour,
    blue: Colour,
    white: Colour,
    coffee: Colour,
    orange: Colour,
    teal: Colour,
    wood_light: Colour,
    wood_dark: Colour,
}

impl Palette {
    fn jittered(rng: &mut SplitMix64) -> Palette {
        let mut c = |r: f64, g: f64, b: f64| {
            let j = DVec3::new(
                rng.uniform(-0.05, 0.05),
                rng.uniform(-0.05, 0.05),
                rng.uniform(-0.05, 0.05),
            );
            (DVec3::new(r, g, b) + j).clamp(DVec3::ZERO, DVec3::ONE)
        };
        Palette {
            red: c(0.80, 0.17, 0.14),
            cream: c(0.93, 0.86, 0.68),
            blue: c(0.16, 0.33, 0.74),
            white: c(0.95, 0.95, 0.92),
            coffee: c(0.26, 0.14, 0.07),
            orange: c(0.95, 0.52, 0.10),
            teal: c(0.12, 0.58, 0.48),
            wood_light: c(0.74, 0.54, 0.33),
            wood_dark: c(0.50, 0.32, 0.17),
        }
    }
}

impl DemoWorld {
    pub fn generate(seed: u64) -> DemoWorld {
        let mut rng = SplitMix64::new(seed);
        let palette = Palette::jittered(&mut rng);
        let mut parts = vec![room(&mut rng)];
        parts.extend(table(&palette, &mut rng));
        let top = TABLE_HEIGHT;

        let scale = |rng: &mut SplitMix64| rng.uniform(0.9, 1.1);
        let box_size = DVec3::new(0.20, 0.15, 0.14) * scale(&mut rng);
        let (mug_radius, mug_height) = (0.06 * scale(&mut rng), 0.13 * scale(&mut rng));
        let ball_radius = 0.075 * scale(&mut rng);
        let (cone_radius, cone_height) = (0.075 * scale(&mut rng), 0.2 * scale(&mut rng));
        let handle_reach = 0.045;
        let footprints = [
            (box_size.truncate() * 0.5).length(),
            mug_radius + handle_reach,
            ball_radius,
            cone_radius,
        ];
        let spots = place_objects(&footprints, &mut rng);

        let box_yaw = rng.uniform(0.0, std::f64::consts::PI);
        parts.push(Part {
            shape: Shape::cuboid(spots[0].extend(top + box_size.z * 0.5), box_size, box_yaw),
            texture: Texture::Checker {
                a: palette.red,
                b: palette.cream,
                cell: box_size.z / 3.0,
            },
            class: BOX,
        });

        let mug_base = spots[1].extend(top);
        parts.push(Part {
            shape: Shape::Cylinder {
                base: mug_base,
                radius: mug_radius,
                height: mug_height,
            },
            texture: Texture::Stripes {
                a: palette.blue,
                b: palette.cream,
                period: mug_height / 7.0,
                top: palette.coffee,
            },
            class: MUG,
        });
        let handle_yaw = rng.uniform(0.0, std::f64::consts::TAU);
        parts.extend(
            mug_handle(mug_base, mug_radius, mug_height, handle_yaw, handle_reach).map(|shape| Part {
                shape,
                texture: Texture::Plain(palette.blue),
                class: MUG,
            }),
        );

        parts.push(Part {
            shape: Shape::Sphere {
                centre: spots[2].extend(top + ball_radius),
                radius: ball_radius,
            },
            texture: Texture::Dots {
                base: palette.red,
                dot: palette.white,
                spacing: 0.045,
                radius: 0.013,
            },
            class: BALL,
        });

        parts.push(Part {
            shape: Shape::Cone {
                base: spots[3].extend(top),
                radius: cone_radius,
                height: cone_height,
            },
            texture: Texture::Spiral {
                a: palette.orange,
                b: palette.teal,
                turns: 2.0,
                pitch: cone_height / 2.5,
            },
            class: CONE,
        });

        let cluster = cluster_box(&parts[1..]);
        let part_spheres = parts.iter().map(|p| p.shape.bounding_sphere()).collect();
        DemoWorld {
            parts,
            part_spheres,
            cluster,
        }
    }

    /// The same objects and table with no room around them: rays that miss them meet nothing,
    /// as in a NeRF-synthetic render of an object on a plain backdrop.
    pub fn without_room(mut self) -> DemoWorld {
        self.parts.remove(0);
        self.part_spheres.remove(0);
        self
    }

    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// The first surface along `origin + t * dir`, t > 0. Inside the room every ray hits.
    pub fn cast(&self, origin: DVec3, dir: DVec3) -> Option<WorldHit> {
        let ray = Ray { origin, dir };
        let mut best: Option<(usize, SurfaceHit)> = None;
        let mut t_max = f64::INFINITY;
        let near_cluster = self.cluster.intersect(&ray, f64::NEG_INFINITY, f64::INFINITY).is_some()
            || self.cluster.signed_distance(origin) <= 0.0;
        for (i, (part, sphere)) in self.parts.iter().zip(&self.part_spheres).enumerate() {
            if i > 0 && !near_cluster {
                break;
            }
            if sphere.is_some_and(|s| !may_hit_sphere(&ray, t_max, s)) {
                continue;
            }
            if let Some(hit) = part.shape.intersect(&ray, 0.0, t_max) {
                t_max = hit.t;
                best = Some((i, hit));
            }
        }
        best.map(|(part, hit)| WorldHit {
            t: hit.t,
            class: self.parts[part].class,
            point: ray.at(hit.t),
            normal: hit.normal,
            part,
            local: hit.local,
        })
    }

    /// Lambert + ambient shading with a hard shadow from the fixed light.
    pub fn shade(&self, hit: &WorldHit) -> Colour {
        let albedo = self.parts[hit.part].texture.colour(hit.local, hit.normal);
        let to_light = LIGHT - hit.point;
        let lambert = hit.normal.dot(to_light.normalize()).max(0.0);
        let lit = lambert > 0.0 && !self.blocks_light(hit.point + hit.normal * 1e-5, to_light);
        albedo * (AMBIENT + if lit { DIFFUSE * lambert } else { 0.0 })
    }

    /// Whether something other than the room lies between `from` and `from + to_light`.
    fn blocks_light(&self, from: DVec3, to_light: DVec3) -> bool {
        let ray = Ray {
            origin: from,
            dir: to_light,
        };
        self.cluster.intersect(&ray, f64::NEG_INFINITY, f64::INFINITY).is_some()
            && self.parts[1..].iter().zip(&self.part_spheres[1..]).any(|(p, s)| {
                s.is_none_or(|s| may_hit_sphere(&ray, 1.0, s)) && p.shape.intersect(&ray, 0.0, 1.0).is_some()
            })
    }

    /// Exact signed distance to the scene's surfaces (positive in the free space of the room).
    /// It is computed without the ray code, so it can check renders.
    pub fn distance(&self, p: DVec3) -> f64 {
        let room = self.parts[0].shape.signed_distance(p);
        self.parts[1..]
            .iter()
            .map(|part| part.shape.signed_distance(p))
            .fold(room, f64::min)
    }

    /// Distance from `p` to the nearest surface of a part of `class` (infinite for no part).
    pub fn distance_to_class(&self, class: u8, p: DVec3) -> f64 {
        self.parts
            .iter()
            .filter(|part| part.class == class)
            .map(|part| part.shape.signed_distance(p).abs())
            .fold(f64::INFINITY, f64::min)
    }

    /// The room: everything a camera inside it can see.
    pub fn bounds(&self) -> Bounds {
        Bounds {
            min: ROOM_MIN.to_array(),
            max: ROOM_MAX.to_array(),
        }
    }

    /// Where the cameras look: a little above the middle of the table top.
    pub fn look_target(&self) -> DVec3 {
        DVec3::new(0.0, 0.0, TABLE_HEIGHT + 0.06)
    }

    /// Table-top half extents, for the placement checks.
    pub fn table_half_size(&self) -> DVec3 {
        TABLE_SIZE * 0.5
    }
}

fn room(rng: &mut SplitMix64) -> Part {
    let mut c = |r: f64, g: f64, b: f64| DVec3::new(r, g, b) + DVec3::splat(rng.uniform(-0.04, 0.04));
    Part {
        shape: Shape::RoomInterior {
            min: ROOM_MIN,
            max: ROOM_MAX,
        },
        texture: Texture::Room {
            tile_a: c(0.56, 0.56, 0.58),
            tile_b: c(0.42, 0.43, 0.46),
            grout: c(0.28, 0.28, 0.28),
            wall: c(0.80, 0.79, 0.72),
            skirting: c(0.36, 0.30, 0.27),
            ceiling: c(0.92, 0.92, 0.90),
            salt: rng.next_u64(),
        },
        class: BACKGROUND,
    }
}

/// The top and four legs, all of wood.
fn table(palette: &Palette, rng: &mut SplitMix64) -> Vec<Part> {
    let wood = Texture::Wood {
        light: palette.wood_light,
        dark: palette.wood_dark,
        salt: rng.next_u64(),
    };
    let top_centre = DVec3::new(0.0, 0.0, TABLE_HEIGHT - TABLE_SIZE.z * 0.5);
    let mut parts = vec![Part {
        shape: Shape::cuboid(top_centre, TABLE_SIZE, 0.0),
        texture: wood,
        class: TABLE,
    }];
    let leg_height = TABLE_HEIGHT - TABLE_SIZE.z;
    let (lx, ly) = (TABLE_SIZE.x * 0.5 - LEG_INSET, TABLE_SIZE.y * 0.5 - LEG_INSET);
    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let centre = DVec3::new(sx * lx, sy * ly, leg_height * 0.5);
        let size = DVec3::new(LEG_SIDE, LEG_SIDE, leg_height);
        parts.push(Part {
            shape: Shape::cuboid(centre, size, 0.0),
            texture: wood,
            class: TABLE,
        });
    }
    parts
}

/// A squared-off C of three bars on the side of the mug facing `yaw`.
fn mug_handle(base: DVec3, radius: f64, height: f64, yaw: f64, reach: f64) -> [Shape; 3] {
    let out = DVec3::new(yaw.cos(), yaw.sin(), 0.0);
    let bar = 0.014;
    // The arms start a little inside the wall so no gap shows where they join it.
    let arm_len = reach + 0.005;
    let arm_centre = base + out * (radius - 0.005 + arm_len * 0.5);
    let upright_height = height * 0.5 + bar;
    [
        Shape::cuboid(arm_centre + DVec3::Z * height * 0.8, DVec3::new(arm_len, bar, bar), yaw),
        Shape::cuboid(arm_centre + DVec3::Z * height * 0.3, DVec3::new(arm_len, bar, bar), yaw),
        Shape::cuboid(
            base + out * (radius + reach - bar * 0.5) + DVec3::Z * height * 0.55,
            DVec3::new(bar, bar, upright_height),
            yaw,
        ),
    ]
}

/// Centres (on the table top) for objects of the given footprint radii: one per quadrant
/// around the table centre, so each view sees all of them and some hide parts of others.
/// Which object gets which quadrant, the rotation and the distances are drawn from `rng`;
/// draws that collide or leave the table are redrawn.
fn place_objects(footprints: &[f64; 4], rng: &mut SplitMix64) -> [glam::DVec2; 4] {
    let half = TABLE_SIZE.truncate() * 0.5;
    let mut quadrants = [0usize, 1, 2, 3];
    rng.shuffle(&mut quadrants);
    let spin = rng.uniform(0.0, std::f64::consts::TAU);
    let spot = |quadrant: usize, angle_jitter: f64, distance: f64| {
        let angle = spin + quadrant as f64 * std::f64::consts::FRAC_PI_2 + angle_jitter;
        glam::DVec2::new(angle.cos(), angle.sin()) * distance
    };
    for _ in 0..1000 {
        let spots: [glam::DVec2; 4] =
            std::array::from_fn(|i| spot(quadrants[i], rng.uniform(-0.25, 0.25), rng.uniform(0.17, 0.26)));
        if layout_fits(&spots, footprints, half) {
            return spots;
        }
    }
    // Unreachable in practice (a test draws many seeds); a layout that always fits the table.
    let fallback: [glam::DVec2; 4] = std::array::from_fn(|i| {
        let angle = std::f64::consts::FRAC_PI_4 + i as f64 * std::f64::consts::FRAC_PI_2;
        glam::DVec2::new(angle.cos(), angle.sin()) * 0.22
    });
    debug_assert!(layout_fits(&fallback, footprints, half));
    fallback
}

/// No two footprints touch and all stay on the table, with `CLEARANCE` to spare.
fn layout_fits(spots: &[glam::DVec2; 4], footprints: &[f64; 4], table_half: glam::DVec2) -> bool {
    let on_table = spots
        .iter()
        .zip(footprints)
        .all(|(s, r)| s.x.abs() + r + CLEARANCE <= table_half.x && s.y.abs() + r + CLEARANCE <= table_half.y);
    let apart =
        (0..4).all(|i| (i + 1..4).all(|j| spots[i].distance(spots[j]) >= footprints[i] + footprints[j] + CLEARANCE));
    on_table && apart
}

/// An axis-aligned box around the parts (grown a little) as a shape, for early outs.
fn cluster_box(parts: &[Part]) -> Shape {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for part in parts {
        let r = part.shape.footprint_radius();
        let (centre, top) = match part.shape {
            Shape::Cuboid { centre, half, .. } => (centre, centre.z + half.z),
            Shape::Sphere { centre, radius } => (centre, centre.z + radius),
            Shape::Cylinder { base, height, .. } | Shape::Cone { base, height, .. } => (base, base.z + height),
            Shape::RoomInterior { min, max } => ((min + max) * 0.5, max.z),
        };
        lo = lo.min(DVec3::new(centre.x - r, centre.y - r, part.shape.bottom()));
        hi = hi.max(DVec3::new(centre.x + r, centre.y + r, top));
    }
    let margin = DVec3::splat(0.01);
    Shape::cuboid((lo + hi) * 0.5, hi - lo + margin * 2.0, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parts that stand on the table (all but the mug's handle bars), with their axes.
    fn standing_objects(world: &DemoWorld) -> Vec<(u8, glam::DVec2, &Shape)> {
        world
            .parts()
            .iter()
            .filter(|p| p.class > TABLE && !(p.class == MUG && matches!(p.shape, Shape::Cuboid { .. })))
            .map(|p| {
                let axis = match p.shape {
                    Shape::Cuboid { centre, .. } | Shape::Sphere { centre, .. } => centre.truncate(),
                    Shape::Cylinder { base, .. } | Shape::Cone { base, .. } => base.truncate(),
                    Shape::RoomInterior { .. } => unreachable!("the room is class 0"),
                };
                (p.class, axis, &p.shape)
            })
            .collect()
    }

    #[test]
    fn objects_stand_on_the_table_apart_from_each_other_for_many_seeds() {
        for seed in 0..500 {
            let world = DemoWorld::generate(seed);
            let objects = standing_objects(&world);
            let classes: Vec<u8> = objects.iter().map(|o| o.0).collect();
            assert_eq!(classes, [BOX, MUG, BALL, CONE]);
            let mug = world
                .parts()
                .iter()
                .find(|p| p.class == MUG)
                .unwrap()
                .shape
                .footprint_radius();
            let footprints: Vec<f64> = objects
                .iter()
                .map(|(c, _, s)| if *c == MUG { mug + 0.045 } else { s.footprint_radius() })
                .collect();
            for (i, (_, axis, shape)) in objects.iter().enumerate() {
                assert!(
                    (shape.bottom() - TABLE_HEIGHT).abs() < 1e-12,
                    "seed {seed}: {shape:?} does not stand on the table"
                );
                let half = world.table_half_size();
                assert!(
                    axis.x.abs() + footprints[i] < half.x && axis.y.abs() + footprints[i] < half.y,
                    "seed {seed}"
                );
                for (j, (_, other, _)) in objects.iter().enumerate().skip(i + 1) {
                    assert!(
                        axis.distance(*other) > footprints[i] + footprints[j],
                        "seed {seed}: objects {i} and {j} touch"
                    );
                }
            }
        }
    }

    #[test]
    fn mug_handle_touches_the_mug() {
        let world = DemoWorld::generate(3);
        let mug = world.parts().iter().find(|p| p.class == MUG).unwrap();
        let bars: Vec<&Part> = world
            .parts()
            .iter()
            .filter(|p| p.class == MUG && matches!(p.shape, Shape::Cuboid { .. }))
            .collect();
        assert_eq!(bars.len(), 3);
        let Shape::Cylinder { base, radius, height } = mug.shape else {
            panic!("the mug is a cylinder")
        };
        // The arms reach into the wall; the upright stands clear of it.
        let touching = bars
            .iter()
            .filter(|b| {
                (0..=40).any(|k| {
                    let a = k as f64 / 40.0 * std::f64::consts::TAU;
                    (0..=20).any(|h| {
                        let p = base + DVec3::new(a.cos() * radius, a.sin() * radius, height * h as f64 / 20.0);
                        b.shape.signed_distance(p) < 0.0
                    })
                })
            })
            .count();
        assert_eq!(touching, 2);
    }

    #[test]
    fn different_seeds_move_objects_and_change_colours() {
        let a = DemoWorld::generate(1);
        let b = DemoWorld::generate(2);
        let centres = |w: &DemoWorld| format!("{:?}", w.parts().iter().map(|p| p.shape).collect::<Vec<_>>());
        assert_ne!(centres(&a), centres(&b));
        assert_eq!(centres(&a), centres(&DemoWorld::generate(1)));
    }

    #[test]
    fn every_ray_from_inside_the_room_hits_something() {
        let world = DemoWorld::generate(0);
        let mut rng = SplitMix64::new(9);
        for _ in 0..2000 {
            let dir = DVec3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
            let hit = world
                .cast(DVec3::new(1.0, -0.5, 1.3), dir)
                .expect("the room closes every ray");
            assert!(world.distance(hit.point).abs() < 1e-9);
        }
    }

    #[test]
    fn the_early_out_box_never_changes_what_a_ray_hits() {
        let world = DemoWorld::generate(4);
        let mut rng = SplitMix64::new(10);
        for _ in 0..5000 {
            let origin = DVec3::new(rng.uniform(-1.5, 1.5), rng.uniform(-1.4, 1.4), rng.uniform(1.0, 2.0));
            let target = DVec3::new(rng.uniform(-0.7, 0.7), rng.uniform(-0.5, 0.5), rng.uniform(0.0, 1.2));
            let ray = Ray {
                origin,
                dir: target - origin,
            };
            let brute = world
                .parts()
                .iter()
                .enumerate()
                .filter_map(|(i, p)| p.shape.intersect(&ray, 0.0, f64::INFINITY).map(|h| (i, h.t)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            let hit = world.cast(origin, target - origin).unwrap();
            assert_eq!((hit.part, hit.t), brute);
        }
    }

    #[test]
    fn shadows_fall_behind_objects_from_the_light() {
        let world = DemoWorld::generate(0);
        let ball = world.parts().iter().find(|p| p.class == BALL).unwrap();
        let Shape::Sphere { centre, .. } = ball.shape else {
            panic!("the ball is a sphere")
        };
        // Where the line from the light through the ball's centre meets the table top.
        let away_from_light = (centre - LIGHT).normalize();
        let shadowed = centre + away_from_light * ((TABLE_HEIGHT - centre.z) / away_from_light.z);
        assert!(world.distance_to_class(TABLE, shadowed) < 1e-9);
        assert!(world.blocks_light(shadowed + DVec3::Z * 1e-5, LIGHT - shadowed));
        // The table corner nearest the light is in the open.
        let half = world.table_half_size();
        let open = DVec3::new(half.x - 0.02, -half.y + 0.02, TABLE_HEIGHT);
        assert!(!world.blocks_light(open + DVec3::Z * 1e-5, LIGHT - open));
    }
}
