//! The demo scene's primitives: analytic ray intersection for rendering and exact signed
//! distances, which are an independent description of the same surfaces for checking renders.
//! World axes: metres, z up.
use glam::{DVec2, DVec3};

/// `origin + t * dir`. `dir` need not be unit length: the renderer passes camera rays whose
/// camera-space z is 1, so `t` of a hit is its z-depth.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: DVec3,
    pub dir: DVec3,
}

impl Ray {
    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + self.dir * t
    }
}

/// Where a ray meets a surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub t: f64,
    /// Unit outward normal (inward for the room, which is seen from inside).
    pub normal: DVec3,
    /// Hit point in the shape's own frame, so textures stick to the shape.
    pub local: DVec3,
}

/// Solid primitives. The vertical ones stand on `base` (the centre of their bottom face).
#[derive(Clone, Copy, Debug)]
pub enum Shape {
    /// The inside of an axis-aligned box: walls, floor and ceiling of the room.
    RoomInterior {
        min: DVec3,
        max: DVec3,
    },
    /// A box turned by a yaw about the vertical axis through its centre.
    Cuboid {
        centre: DVec3,
        half: DVec3,
        cos_yaw: f64,
        sin_yaw: f64,
    },
    Sphere {
        centre: DVec3,
        radius: f64,
    },
    /// A closed vertical cylinder.
    Cylinder {
        base: DVec3,
        radius: f64,
        height: f64,
    },
    /// A vertical cone with its apex up, closed by its base disc.
    Cone {
        base: DVec3,
        radius: f64,
        height: f64,
    },
}

impl Shape {
    pub fn cuboid(centre: DVec3, size: DVec3, yaw: f64) -> Shape {
        Shape::Cuboid {
            centre,
            half: size * 0.5,
            cos_yaw: yaw.cos(),
            sin_yaw: yaw.sin(),
        }
    }

    /// The nearest intersection with `t` in (t_min, t_max).
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
        match *self {
            Shape::RoomInterior { min, max } => room_exit(ray, min, max, t_min, t_max),
            Shape::Cuboid {
                centre,
                half,
                cos_yaw,
                sin_yaw,
            } => {
                let local_ray = Ray {
                    origin: rotate_z(ray.origin - centre, cos_yaw, -sin_yaw),
                    dir: rotate_z(ray.dir, cos_yaw, -sin_yaw),
                };
                let mut hit = slab_entry(&local_ray, half, t_min, t_max)?;
                hit.normal = rotate_z(hit.normal, cos_yaw, sin_yaw);
                Some(hit)
            }
            Shape::Sphere { centre, radius } => {
                let o = ray.origin - centre;
                let t = nearest_root(
                    ray.dir.length_squared(),
                    2.0 * o.dot(ray.dir),
                    o.length_squared() - radius * radius,
                    |t| t > t_min && t < t_max,
                )?;
                let local = o + ray.dir * t;
                Some(SurfaceHit {
                    t,
                    normal: local / radius,
                    local,
                })
            }
            Shape::Cylinder { base, radius, height } => cylinder_hit(ray, base, radius, height, t_min, t_max),
            Shape::Cone { base, radius, height } => cone_hit(ray, base, radius, height, t_min, t_max),
        }
    }

    /// Exact signed distance: negative inside the solid (for the room: positive inside it,
    /// where the cameras are, since the room is seen from within).
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        match *self {
            Shape::RoomInterior { min, max } => (p - min).min(max - p).min_element(),
            Shape::Cuboid {
                centre,
                half,
                cos_yaw,
                sin_yaw,
            } => {
                let q = rotate_z(p - centre, cos_yaw, -sin_yaw).abs() - half;
                q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
            }
            Shape::Sphere { centre, radius } => (p - centre).length() - radius,
            Shape::Cylinder { base, radius, height } => {
                let (rho, z) = profile_coords(p - base);
                let d = DVec2::new(rho - radius, (z - height * 0.5).abs() - height * 0.5);
                d.max(DVec2::ZERO).length() + d.max_element().min(0.0)
            }
            Shape::Cone { base, radius, height } => {
                let (rho, z) = profile_coords(p - base);
                // The profile touches the axis, so mirroring it across rho = 0 gives a triangle
                // whose 2D distance is the solid's 3D distance.
                let profile = [
                    DVec2::new(-radius, 0.0),
                    DVec2::new(radius, 0.0),
                    DVec2::new(0.0, height),
                ];
                convex_polygon_distance(&profile, DVec2::new(rho, z))
            }
        }
    }

    /// A sphere (centre, radius) holding the solid, for cheap rejection of rays that pass
    /// far from it; None for the room, which every ray hits.
    pub fn bounding_sphere(&self) -> Option<(DVec3, f64)> {
        match *self {
            Shape::RoomInterior { .. } => None,
            Shape::Cuboid { centre, half, .. } => Some((centre, half.length())),
            Shape::Sphere { centre, radius } => Some((centre, radius)),
            Shape::Cylinder { base, radius, height } | Shape::Cone { base, radius, height } => Some((
                base + DVec3::Z * height * 0.5,
                DVec2::new(radius, height * 0.5).length(),
            )),
        }
    }

    /// Radius of a vertical cylinder around the shape's axis that holds it (for placement).
    pub fn footprint_radius(&self) -> f64 {
        match *self {
            Shape::RoomInterior { min, max } => (max - min).truncate().length() * 0.5,
            Shape::Cuboid { half, .. } => half.truncate().length(),
            Shape::Sphere { radius, .. } | Shape::Cylinder { radius, .. } | Shape::Cone { radius, .. } => radius,
        }
    }

    /// Lowest z of the solid.
    pub fn bottom(&self) -> f64 {
        match *self {
            Shape::RoomInterior { min, .. } => min.z,
            Shape::Cuboid { centre, half, .. } => centre.z - half.z,
            Shape::Sphere { centre, radius } => centre.z - radius,
            Shape::Cylinder { base, .. } | Shape::Cone { base, .. } => base.z,
        }
    }
}

/// Whether `ray` can meet the sphere (centre, radius) with t below `t_max`: a necessary
/// condition for hitting anything inside it, far cheaper than most exact tests.
pub fn may_hit_sphere(ray: &Ray, t_max: f64, (centre, radius): (DVec3, f64)) -> bool {
    let to_centre = centre - ray.origin;
    let dd = ray.dir.length_squared();
    let along = to_centre.dot(ray.dir) / dd;
    let miss_distance_sq = (to_centre - ray.dir * along).length_squared();
    if miss_distance_sq > radius * radius {
        return false;
    }
    // The nearest point of the sphere along the ray lies beyond t_max.
    along - ((radius * radius - miss_distance_sq) / dd).sqrt() < t_max
}

/// Rotates `v` about z by the angle whose cosine and sine are given.
fn rotate_z(v: DVec3, cos: f64, sin: f64) -> DVec3 {
    DVec3::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y, v.z)
}

/// (distance from the vertical axis, height) of a point relative to a shape's base.
fn profile_coords(local: DVec3) -> (f64, f64) {
    (local.truncate().length(), local.z)
}

/// The smallest root of a t^2 + b t + c that `accept` takes.
fn nearest_root(a: f64, b: f64, c: f64, accept: impl Fn(f64) -> bool) -> Option<f64> {
    if a.abs() < 1e-14 {
        if b.abs() < 1e-14 {
            return None;
        }
        let t = -c / b;
        return accept(t).then_some(t);
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    // The numerically stable pair: no cancellation between b and the root.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    let (lo, hi) = if r0 <= r1 { (r0, r1) } else { (r1, r0) };
    [lo, hi].into_iter().find(|&t| accept(t))
}

/// Where a ray from inside an axis-aligned box leaves it.
fn room_exit(ray: &Ray, min: DVec3, max: DVec3, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
    let mut best: Option<(f64, usize)> = None;
    for axis in 0..3 {
        let d = ray.dir[axis];
        if d == 0.0 {
            continue;
        }
        let wall = if d > 0.0 { max[axis] } else { min[axis] };
        let t = (wall - ray.origin[axis]) / d;
        if t > t_min && t < t_max && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, axis));
        }
    }
    let (t, axis) = best?;
    let mut normal = DVec3::ZERO;
    normal[axis] = -ray.dir[axis].signum();
    Some(SurfaceHit {
        t,
        normal,
        local: ray.at(t),
    })
}

/// Where a ray enters an origin-centred box of half extents `half` (slab method).
fn slab_entry(ray: &Ray, half: DVec3, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
    let mut t_near = f64::NEG_INFINITY;
    let mut t_far = f64::INFINITY;
    let mut near_axis = 0;
    for axis in 0..3 {
        let (o, d, h) = (ray.origin[axis], ray.dir[axis], half[axis]);
        if d == 0.0 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((-h - o) / d, (h - o) / d);
        let (enter, exit) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
        if enter > t_near {
            t_near = enter;
            near_axis = axis;
        }
        t_far = t_far.min(exit);
    }
    // A ray starting inside a solid (never the case for cameras or offset shadow rays) sees
    // no entry and is treated as a miss.
    if t_near > t_far || t_near <= t_min || t_near >= t_max {
        return None;
    }
    let mut normal = DVec3::ZERO;
    normal[near_axis] = -ray.dir[near_axis].signum();
    Some(SurfaceHit {
        t: t_near,
        normal,
        local: ray.at(t_near),
    })
}

/// Nearest of the candidate hits (side surface and flat caps) of a vertical solid.
fn nearest(candidates: impl IntoIterator<Item = Option<SurfaceHit>>) -> Option<SurfaceHit> {
    candidates.into_iter().flatten().min_by(|a, b| a.t.total_cmp(&b.t))
}

/// A horizontal disc of `radius` at height `z` (local frame), facing up or down.
fn disc_hit(ray: &Ray, z: f64, radius: f64, up: bool, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
    if ray.dir.z == 0.0 {
        return None;
    }
    let t = (z - ray.origin.z) / ray.dir.z;
    let local = ray.at(t);
    let inside = local.truncate().length_squared() <= radius * radius;
    (t > t_min && t < t_max && inside).then_some(SurfaceHit {
        t,
        normal: if up { DVec3::Z } else { DVec3::NEG_Z },
        local,
    })
}

fn cylinder_hit(ray: &Ray, base: DVec3, radius: f64, height: f64, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
    let r = Ray {
        origin: ray.origin - base,
        dir: ray.dir,
    };
    let (o, d) = (r.origin, r.dir);
    let a = d.x * d.x + d.y * d.y;
    let side = if a == 0.0 {
        None
    } else {
        nearest_root(
            a,
            2.0 * (o.x * d.x + o.y * d.y),
            o.x * o.x + o.y * o.y - radius * radius,
            |t| {
                let z = o.z + d.z * t;
                t > t_min && t < t_max && (0.0..=height).contains(&z)
            },
        )
        .map(|t| {
            let local = r.at(t);
            SurfaceHit {
                t,
                normal: DVec3::new(local.x, local.y, 0.0) / radius,
                local,
            }
        })
    };
    nearest([
        side,
        disc_hit(&r, height, radius, true, t_min, t_max),
        disc_hit(&r, 0.0, radius, false, t_min, t_max),
    ])
}

fn cone_hit(ray: &Ray, base: DVec3, radius: f64, height: f64, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
    let r = Ray {
        origin: ray.origin - base,
        dir: ray.dir,
    };
    let (o, d) = (r.origin, r.dir);
    // x^2 + y^2 = k^2 (height - z)^2 with 0 <= z <= height; the z range drops the upper nappe.
    let k2 = (radius / height).powi(2);
    let q = height - o.z;
    let a = d.x * d.x + d.y * d.y - k2 * d.z * d.z;
    let b = 2.0 * (o.x * d.x + o.y * d.y + k2 * q * d.z);
    let c = o.x * o.x + o.y * o.y - k2 * q * q;
    let side = nearest_root(a, b, c, |t| {
        let z = o.z + d.z * t;
        t > t_min && t < t_max && (0.0..=height).contains(&z)
    })
    .map(|t| {
        let local = r.at(t);
        let normal = DVec3::new(local.x, local.y, k2 * (height - local.z)).normalize_or(DVec3::Z);
        SurfaceHit { t, normal, local }
    });
    nearest([side, disc_hit(&r, 0.0, radius, false, t_min, t_max)])
}

/// Signed distance from `p` to a convex polygon with counter-clockwise corners.
fn convex_polygon_distance(corners: &[DVec2], p: DVec2) -> f64 {
    let mut nearest_edge = f64::INFINITY;
    let mut inside = true;
    for (i, &a) in corners.iter().enumerate() {
        let b = corners[(i + 1) % corners.len()];
        let edge = b - a;
        let h = ((p - a).dot(edge) / edge.length_squared()).clamp(0.0, 1.0);
        nearest_edge = nearest_edge.min((p - a - edge * h).length());
        if edge.perp_dot(p - a) < 0.0 {
            inside = false;
        }
    }
    if inside { -nearest_edge } else { nearest_edge }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Test shapes with a point inside each.
    fn shapes_and_inner_points() -> Vec<(Shape, DVec3)> {
        vec![
            (
                Shape::cuboid(DVec3::new(0.1, -0.2, 0.3), DVec3::new(0.3, 0.2, 0.1), 0.7),
                DVec3::new(0.1, -0.2, 0.3),
            ),
            (
                Shape::Sphere {
                    centre: DVec3::new(-0.1, 0.2, 0.1),
                    radius: 0.25,
                },
                DVec3::new(-0.1, 0.2, 0.1),
            ),
            (
                Shape::Cylinder {
                    base: DVec3::new(0.2, 0.1, -0.1),
                    radius: 0.15,
                    height: 0.4,
                },
                DVec3::new(0.2, 0.1, 0.1),
            ),
            (
                Shape::Cone {
                    base: DVec3::new(-0.2, -0.1, -0.2),
                    radius: 0.2,
                    height: 0.5,
                },
                DVec3::new(-0.2, -0.1, -0.1),
            ),
        ]
    }

    fn shapes() -> Vec<Shape> {
        shapes_and_inner_points().into_iter().map(|(s, _)| s).collect()
    }

    fn random_unit(rng: &mut SplitMix64) -> DVec3 {
        loop {
            let v = DVec3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
            if (0.01..1.0).contains(&v.length_squared()) {
                return v.normalize();
            }
        }
    }

    #[test]
    fn known_hits_have_the_expected_distance_and_normal() {
        let ray = Ray {
            origin: DVec3::new(0.0, 0.0, 5.0),
            dir: DVec3::new(0.0, 0.0, -2.0),
        };
        let sphere = Shape::Sphere {
            centre: DVec3::ZERO,
            radius: 1.0,
        };
        let hit = sphere.intersect(&ray, 0.0, f64::INFINITY).unwrap();
        assert!((hit.t - 2.0).abs() < 1e-12 && (hit.normal - DVec3::Z).length() < 1e-12);

        let cyl = Shape::Cylinder {
            base: DVec3::ZERO,
            radius: 1.0,
            height: 1.0,
        };
        let hit = cyl.intersect(&ray, 0.0, f64::INFINITY).unwrap();
        assert!((hit.t - 2.0).abs() < 1e-12 && hit.normal == DVec3::Z);
        let side = Ray {
            origin: DVec3::new(3.0, 0.0, 0.5),
            dir: DVec3::NEG_X,
        };
        let hit = cyl.intersect(&side, 0.0, f64::INFINITY).unwrap();
        assert!((hit.t - 2.0).abs() < 1e-12 && (hit.normal - DVec3::X).length() < 1e-12);

        let cone = Shape::Cone {
            base: DVec3::ZERO,
            radius: 1.0,
            height: 1.0,
        };
        let hit = cone.intersect(&ray, 0.0, f64::INFINITY).unwrap();
        assert!((hit.t - 2.0).abs() < 1e-9, "apex at z = 1, t {}", hit.t);
        let hit = cone.intersect(&side, 0.0, f64::INFINITY).unwrap();
        assert!(
            (hit.t - 2.5).abs() < 1e-12,
            "at half height the cone's radius is 0.5, t {}",
            hit.t
        );
        assert!((hit.normal - DVec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-12);

        let turned = Shape::cuboid(DVec3::ZERO, DVec3::new(2.0, 1.0, 1.0), std::f64::consts::FRAC_PI_2);
        let hit = turned.intersect(&side, 0.0, f64::INFINITY).unwrap();
        assert!(
            (hit.t - 2.5).abs() < 1e-12,
            "turned 90 degrees the box is 1 m wide along x, t {}",
            hit.t
        );
        assert!((hit.normal - DVec3::X).length() < 1e-12);
    }

    #[test]
    fn misses_and_the_range_limits_are_respected() {
        let ray = Ray {
            origin: DVec3::new(0.0, 0.0, 5.0),
            dir: DVec3::Z,
        };
        for s in shapes() {
            assert!(
                s.intersect(&ray, 0.0, f64::INFINITY).is_none(),
                "{s:?} is behind the ray"
            );
        }
        let down = Ray {
            origin: DVec3::new(0.0, 0.0, 5.0),
            dir: DVec3::NEG_Z,
        };
        let sphere = Shape::Sphere {
            centre: DVec3::ZERO,
            radius: 1.0,
        };
        assert!(sphere.intersect(&down, 0.0, 3.9).is_none());
        assert!(sphere.intersect(&down, 0.0, 4.1).is_some());
    }

    #[test]
    fn room_is_hit_from_inside_with_inward_normals() {
        let room = Shape::RoomInterior {
            min: DVec3::new(-1.0, -2.0, 0.0),
            max: DVec3::new(1.0, 2.0, 3.0),
        };
        let mut rng = SplitMix64::new(5);
        for _ in 0..1000 {
            let ray = Ray {
                origin: DVec3::new(0.1, 0.2, 1.0),
                dir: random_unit(&mut rng) * 1.7,
            };
            let hit = room
                .intersect(&ray, 0.0, f64::INFINITY)
                .expect("a ray inside the room always hits it");
            assert!(room.signed_distance(hit.local).abs() < 1e-12);
            assert!(hit.normal.dot(ray.dir) < 0.0, "the normal faces the camera inside");
        }
    }

    /// The intersection code and the signed distances are written independently; they must
    /// describe the same surfaces, and nothing may lie between the origin and the hit.
    #[test]
    fn intersections_agree_with_signed_distances() {
        let mut rng = SplitMix64::new(11);
        for (shape, inner) in shapes_and_inner_points() {
            let mut hits = 0;
            for _ in 0..4000 {
                let origin = random_unit(&mut rng) * 2.0;
                let target = inner + DVec3::new(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2));
                let ray = Ray {
                    origin,
                    dir: (target - origin) * rng.uniform(0.5, 2.0),
                };
                let Some(hit) = shape.intersect(&ray, 0.0, f64::INFINITY) else {
                    // A miss: points along the ray stay outside.
                    for i in 0..=50 {
                        let p = ray.at(i as f64 * 0.05);
                        assert!(shape.signed_distance(p) > -1e-9, "{shape:?}: missed ray passes inside");
                    }
                    continue;
                };
                hits += 1;
                let p = ray.at(hit.t);
                assert!(
                    shape.signed_distance(p).abs() < 1e-9,
                    "{shape:?}: hit point off the surface"
                );
                assert!((hit.normal.length() - 1.0).abs() < 1e-9);
                assert!(
                    hit.normal.dot(ray.dir) <= 1e-12,
                    "{shape:?}: normal faces away from the ray"
                );
                let eps = 1e-6 * ray.dir.length();
                assert!(
                    shape.signed_distance(p + hit.normal * eps) > 0.0,
                    "{shape:?}: normal points inward"
                );
                for i in 0..50 {
                    let before = ray.at(hit.t * i as f64 / 50.0);
                    assert!(
                        shape.signed_distance(before) > -1e-9,
                        "{shape:?}: a nearer hit was skipped"
                    );
                }
            }
            assert!(
                hits > 800 && hits < 3900,
                "{shape:?}: only {hits} hits, the test rays are badly aimed"
            );
        }
    }

    #[test]
    fn bounding_spheres_hold_their_shapes_and_never_reject_a_hit() {
        let mut rng = SplitMix64::new(12);
        for (shape, inner) in shapes_and_inner_points() {
            let sphere = shape.bounding_sphere().unwrap();
            for _ in 0..2000 {
                let p = inner + random_unit(&mut rng) * rng.uniform(0.0, 0.6);
                if shape.signed_distance(p) <= 0.0 {
                    assert!((p - sphere.0).length() <= sphere.1 + 1e-12, "{shape:?}: {p} pokes out");
                }
                let origin = random_unit(&mut rng) * 2.0;
                let ray = Ray {
                    origin,
                    dir: (p - origin) * rng.uniform(0.3, 3.0),
                };
                let t_max = rng.uniform(0.0, 3.0);
                if shape.intersect(&ray, 0.0, t_max).is_some() {
                    assert!(may_hit_sphere(&ray, t_max, sphere), "{shape:?}: a hit was rejected");
                }
            }
            let away = Ray {
                origin: sphere.0 + DVec3::X * (sphere.1 + 1.0),
                dir: DVec3::Y,
            };
            assert!(!may_hit_sphere(&away, f64::INFINITY, sphere));
            let short = Ray {
                origin: sphere.0 + DVec3::X * (sphere.1 + 1.0),
                dir: DVec3::NEG_X,
            };
            assert!(!may_hit_sphere(&short, 0.9, sphere) && may_hit_sphere(&short, 1.1, sphere));
        }
    }

    #[test]
    fn signed_distances_are_exact_at_known_points() {
        let cone = Shape::Cone {
            base: DVec3::ZERO,
            radius: 1.0,
            height: 1.0,
        };
        assert!((cone.signed_distance(DVec3::new(0.0, 0.0, 2.0)) - 1.0).abs() < 1e-12);
        assert!((cone.signed_distance(DVec3::new(0.0, 0.0, -0.5)) - 0.5).abs() < 1e-12);
        assert!((cone.signed_distance(DVec3::new(0.0, 0.0, 0.1)) + 0.1).abs() < 1e-12);
        let cyl = Shape::Cylinder {
            base: DVec3::ZERO,
            radius: 1.0,
            height: 2.0,
        };
        assert!((cyl.signed_distance(DVec3::new(0.0, 3.0, 1.0)) - 2.0).abs() < 1e-12);
        assert!((cyl.signed_distance(DVec3::new(2.0, 0.0, 3.0)) - 2f64.sqrt()).abs() < 1e-12);
        let cube = Shape::cuboid(DVec3::ZERO, DVec3::splat(2.0), 0.3);
        assert!((cube.signed_distance(DVec3::ZERO) + 1.0).abs() < 1e-12);
    }
}
