//! Procedural textures, evaluated in each shape's own frame so a pattern stays put on its
//! surface from every view (what makes the frames multi-view consistent).
use glam::DVec3;

use super::noise::lattice_hash;

/// Linear RGB in [0, 1].
pub type Colour = DVec3;

#[derive(Clone, Copy, Debug)]
pub enum Texture {
    /// Wood grain running along local x.
    Wood {
        light: Colour,
        dark: Colour,
        salt: u64,
    },
    /// Tiled floor, plastered walls with a skirting board, plain ceiling; chosen by the normal.
    Room {
        tile_a: Colour,
        tile_b: Colour,
        grout: Colour,
        wall: Colour,
        skirting: Colour,
        ceiling: Colour,
        salt: u64,
    },
    /// 3D checkerboard of cubes of side `cell`.
    Checker {
        a: Colour,
        b: Colour,
        cell: f64,
    },
    /// Horizontal bands of height `period`; upward faces get `top` (the drink in a mug).
    Stripes {
        a: Colour,
        b: Colour,
        period: f64,
        top: Colour,
    },
    /// Round spots where the surface passes near points of a cubic lattice of `spacing`.
    Dots {
        base: Colour,
        dot: Colour,
        spacing: f64,
        radius: f64,
    },
    /// Bands winding up around the vertical axis.
    Spiral {
        a: Colour,
        b: Colour,
        turns: f64,
        pitch: f64,
    },
    Plain(Colour),
}

impl Texture {
    /// Colour at a point given in the shape's frame, with the surface's world normal.
    pub fn colour(&self, local: DVec3, normal: DVec3) -> Colour {
        match *self {
            Texture::Wood { light, dark, salt } => {
                let warp = fbm(local * DVec3::new(1.5, 9.0, 9.0), salt);
                let grain = smoothstep(0.25, 0.75, triangle_wave(local.y * 14.0 + local.z * 9.0 + 2.2 * warp));
                let fibre = 0.92 + 0.08 * value_noise(local * DVec3::new(3.0, 120.0, 120.0), salt ^ 1);
                dark.lerp(light, grain) * fibre
            }
            Texture::Room {
                tile_a,
                tile_b,
                grout,
                wall,
                skirting,
                ceiling,
                salt,
            } => {
                if normal.z > 0.5 {
                    let tile = 0.5;
                    let (u, v) = (local.x / tile, local.y / tile);
                    let seam = |c: f64| (c - c.round()).abs() * tile < 0.006;
                    if seam(u) || seam(v) {
                        return grout;
                    }
                    let even = (u.floor() as i64 + v.floor() as i64).rem_euclid(2) == 0;
                    let base = if even { tile_a } else { tile_b };
                    base * (0.9 + 0.1 * fbm(local * 7.0, salt))
                } else if normal.z < -0.5 {
                    ceiling
                } else if local.z < 0.1 {
                    skirting
                } else {
                    // Walls facing along x and along y differ a little, as lit walls do.
                    let facing = if normal.x.abs() > 0.5 { 1.0 } else { 0.93 };
                    wall * facing * (0.88 + 0.12 * fbm(local * 5.0, salt ^ 2))
                }
            }
            Texture::Checker { a, b, cell } => {
                // Half a cell of offset keeps the box faces (at +-half size) off cell borders.
                let c = (local / cell + 0.5).floor();
                if (c.x as i64 + c.y as i64 + c.z as i64).rem_euclid(2) == 0 {
                    a
                } else {
                    b
                }
            }
            Texture::Stripes { a, b, period, top } => {
                if normal.z > 0.5 {
                    top
                } else if ((local.z / period).floor() as i64).rem_euclid(2) == 0 {
                    a
                } else {
                    b
                }
            }
            Texture::Dots {
                base,
                dot,
                spacing,
                radius,
            } => {
                let q = local / spacing;
                if (q - q.round()).length() < radius / spacing {
                    dot
                } else {
                    base
                }
            }
            Texture::Spiral { a, b, turns, pitch } => {
                let around = local.y.atan2(local.x) / std::f64::consts::TAU;
                if (around * turns + local.z / pitch).rem_euclid(1.0) < 0.5 {
                    a
                } else {
                    b
                }
            }
            Texture::Plain(c) => c,
        }
    }
}

fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// 0 at integers, 1 half way between: a stripe pattern without trigonometry.
fn triangle_wave(x: f64) -> f64 {
    (2.0 * (x - x.floor()) - 1.0).abs()
}

/// Smoothly interpolated lattice values in [0, 1).
pub fn value_noise(p: DVec3, salt: u64) -> f64 {
    let cell = p.floor();
    let f = p - cell;
    let s = f * f * (DVec3::splat(3.0) - 2.0 * f);
    let (x, y, z) = (cell.x as i64, cell.y as i64, cell.z as i64);
    let corner = |dx: i64, dy: i64, dz: i64| lattice_hash(x + dx, y + dy, z + dz, salt);
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), s.x);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), s.x);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), s.x);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), s.x);
    lerp(lerp(x00, x10, s.y), lerp(x01, x11, s.y), s.z)
}

/// Three octaves of value noise, in [0, 1).
pub fn fbm(p: DVec3, salt: u64) -> f64 {
    let octaves = [(1.0, 0.5714), (2.0, 0.2857), (4.0, 0.1429)];
    octaves
        .iter()
        .enumerate()
        .map(|(i, &(freq, weight))| weight * value_noise(p * freq, salt.wrapping_add(i as u64)))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    const RED: Colour = DVec3::new(0.8, 0.1, 0.1);
    const WHITE: Colour = DVec3::new(0.9, 0.9, 0.9);

    #[test]
    fn noise_is_deterministic_bounded_and_varied() {
        let mut values = Vec::new();
        for i in 0..2000 {
            let p = DVec3::new(i as f64 * 0.137, (i as f64 * 0.311).sin() * 5.0, -(i as f64) * 0.07);
            let v = fbm(p, 9);
            assert_eq!(v, fbm(p, 9));
            assert!((0.0..1.0).contains(&v));
            values.push(v);
        }
        let lo = values.iter().cloned().fold(1.0, f64::min);
        let hi = values.iter().cloned().fold(0.0, f64::max);
        assert!(hi - lo > 0.4, "noise spans only {lo}..{hi}");
        assert_ne!(fbm(DVec3::splat(0.3), 1), fbm(DVec3::splat(0.3), 2));
    }

    #[test]
    fn checker_alternates_between_neighbouring_cells() {
        let t = Texture::Checker {
            a: RED,
            b: WHITE,
            cell: 0.1,
        };
        let at = |x: f64| t.colour(DVec3::new(x, 0.0, 0.0), DVec3::X);
        assert_eq!(at(0.0), RED);
        assert_eq!(at(0.1), WHITE);
        assert_eq!(at(-0.1), WHITE);
        assert_eq!(at(0.2), RED);
    }

    #[test]
    fn stripes_band_by_height_and_tops_differ() {
        let coffee = DVec3::new(0.2, 0.1, 0.05);
        let t = Texture::Stripes {
            a: RED,
            b: WHITE,
            period: 0.02,
            top: coffee,
        };
        assert_eq!(t.colour(DVec3::new(0.05, 0.0, 0.01), DVec3::X), RED);
        assert_eq!(t.colour(DVec3::new(0.05, 0.0, 0.03), DVec3::X), WHITE);
        assert_eq!(t.colour(DVec3::new(0.0, 0.0, 0.03), DVec3::Z), coffee);
    }

    #[test]
    fn dots_cover_part_of_a_sphere() {
        let t = Texture::Dots {
            base: RED,
            dot: WHITE,
            spacing: 0.03,
            radius: 0.009,
        };
        let mut dots = 0;
        let n = 2000;
        for i in 0..n {
            // Points spread over a sphere of radius 0.08 (a Fibonacci spiral).
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let phi = i as f64 * 2.399_963;
            let p = DVec3::new((1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z) * 0.08;
            if t.colour(p, p.normalize()) == WHITE {
                dots += 1;
            }
        }
        let share = dots as f64 / n as f64;
        assert!((0.05..0.5).contains(&share), "dots cover {share} of the ball");
    }

    #[test]
    fn spiral_and_wood_show_both_colours() {
        let spiral = Texture::Spiral {
            a: RED,
            b: WHITE,
            turns: 3.0,
            pitch: 0.05,
        };
        let wood = Texture::Wood {
            light: WHITE,
            dark: RED,
            salt: 4,
        };
        let mut spiral_colours = std::collections::HashSet::new();
        let (mut wood_lo, mut wood_hi) = (f64::INFINITY, 0.0f64);
        for i in 0..400 {
            let a = i as f64 * 0.1;
            let p = DVec3::new(0.05 * a.cos(), 0.05 * a.sin(), i as f64 * 0.001);
            spiral_colours.insert(format!("{:?}", spiral.colour(p, DVec3::X)));
            let w = wood
                .colour(DVec3::new(i as f64 * 0.003, i as f64 * 0.002, 0.02), DVec3::Z)
                .x;
            wood_lo = wood_lo.min(w);
            wood_hi = wood_hi.max(w);
        }
        assert_eq!(spiral_colours.len(), 2);
        assert!(
            wood_hi - wood_lo > 0.05,
            "wood grain has no contrast: {wood_lo}..{wood_hi}"
        );
    }

    #[test]
    fn room_picks_floor_walls_and_ceiling_by_normal() {
        let grey = DVec3::splat(0.5);
        let t = Texture::Room {
            tile_a: RED,
            tile_b: WHITE,
            grout: grey,
            wall: WHITE,
            skirting: grey,
            ceiling: DVec3::ONE,
            salt: 0,
        };
        assert_eq!(t.colour(DVec3::new(0.3, 1.0, 2.4), DVec3::NEG_Z), DVec3::ONE);
        assert_eq!(t.colour(DVec3::new(0.25, 0.5, 0.0), DVec3::Z), grey, "on a seam");
        assert_eq!(t.colour(DVec3::new(1.5, 0.3, 0.05), DVec3::NEG_X), grey, "skirting");
        let floor = t.colour(DVec3::new(0.25, 0.25, 0.0), DVec3::Z);
        assert!(floor.x > floor.y, "tile (0, 0) is tile_a");
    }
}
