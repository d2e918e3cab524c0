//! Pinhole intrinsics and camera-to-world poses. Everything inside the crate uses OpenCV camera
//! axes (x right, y down, z forward); importers convert at the boundary.
use glam::{DMat3, DMat4, DVec3, Mat4, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics for the same camera after resizing the image from `from` to `to` pixels.
    /// Pixel centres map to pixel centres, so the principal point shifts by the half-pixel.
    pub fn scaled(&self, from: (u32, u32), to: (u32, u32)) -> Intrinsics {
        let sx = to.0 as f64 / from.0 as f64;
        let sy = to.1 as f64 / from.1 as f64;
        Intrinsics {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
        }
    }

    /// Direction in camera space (z = 1) through the given pixel coordinate
    /// (integer coordinates are pixel centres).
    pub fn ray_dir(&self, u: f64, v: f64) -> DVec3 {
        DVec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// Checks the values are finite and positive where they must be, in f64 and again as the
    /// f32 the GPU and the page work in; `problem` text naming the field and value otherwise.
    pub fn check(&self) -> Result<(), String> {
        let fields = [("fx", self.fx), ("fy", self.fy), ("cx", self.cx), ("cy", self.cy)];
        if fields.iter().any(|(_, v)| !v.is_finite()) {
            return Err(format!("intrinsics must be finite, got {self:?}"));
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(format!(
                "focal lengths must be positive, got fx={} fy={}",
                self.fx, self.fy
            ));
        }
        for (field, v) in fields {
            f32_finite("intrinsics", field, v)?;
        }
        // A focal length that is subnormal (or zero) as f32 makes 1/f infinite in the shaders.
        for (field, v) in [("fx", self.fx), ("fy", self.fy)] {
            if (v as f32) < f32::MIN_POSITIVE {
                return Err(format!(
                    "intrinsics {field} = {v:e} is too small for a 32-bit float (at least {:e})",
                    f32::MIN_POSITIVE
                ));
            }
        }
        Ok(())
    }
}

/// `value` (`what`'s `field`) must stay finite when narrowed to f32: the GPU and the page use
/// f32, so a value that is fine as f64 (1e301) would become infinite there.
pub fn f32_finite(what: &str, field: &str, value: f64) -> Result<(), String> {
    if (value as f32).is_finite() {
        Ok(())
    } else {
        Err(format!(
            "{what} {field} = {value:e} is outside the 32-bit float range (|value| <= {:e})",
            f32::MAX
        ))
    }
}

/// A rigid camera-to-world transform, stored row-major in files as 16 numbers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose(pub DMat4);

/// How far from orthonormal a rotation may be before a pose is rejected (text files carry
/// 6-9 significant digits, so exact orthonormality cannot be demanded).
const RIGID_TOLERANCE: f64 = 1e-3;

impl Pose {
    pub fn identity() -> Pose {
        Pose(DMat4::IDENTITY)
    }

    /// From 16 numbers in row-major order, as written in pose text files and scene.json.
    pub fn from_row_major(m: &[f64; 16]) -> Pose {
        Pose(DMat4::from_cols_array(m).transpose())
    }

    pub fn to_row_major(&self) -> [f64; 16] {
        self.0.transpose().to_cols_array()
    }

    pub fn rotation(&self) -> DMat3 {
        DMat3::from_mat4(self.0)
    }

    pub fn translation(&self) -> DVec3 {
        self.0.w_axis.truncate()
    }

    /// Camera centre in world coordinates.
    pub fn position(&self) -> DVec3 {
        self.translation()
    }

    pub fn inverse(&self) -> Pose {
        let r = self.rotation().transpose();
        let t = -(r * self.translation());
        Pose(DMat4::from_cols(
            r.x_axis.extend(0.0),
            r.y_axis.extend(0.0),
            r.z_axis.extend(0.0),
            t.extend(1.0),
        ))
    }

    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.0.transform_point3(p)
    }

    pub fn transform_vector(&self, v: DVec3) -> DVec3 {
        self.0.transform_vector3(v)
    }

    /// Converts a camera-to-world pose given in OpenGL/NeRF camera axes (x right, y up,
    /// z backward) to OpenCV axes by flipping the camera's y and z axes.
    pub fn from_opengl(gl: DMat4) -> Pose {
        Pose(gl * DMat4::from_diagonal(glam::DVec4::new(1.0, -1.0, -1.0, 1.0)))
    }

    pub fn as_mat4(&self) -> Mat4 {
        self.0.as_mat4()
    }

    pub fn position_f32(&self) -> Vec3 {
        self.position().as_vec3()
    }

    /// Checks the pose is finite, has a last row of (0 0 0 1) and an orthonormal, right-handed
    /// rotation; `problem` text otherwise.
    pub fn check(&self) -> Result<(), String> {
        let a = self.to_row_major();
        if a.iter().any(|v| !v.is_finite()) {
            return Err("pose has non-finite values".into());
        }
        // Every importer and the archive reader check poses here, so one that the GPU would see
        // as infinite (1e300 is finite in f64 only) is refused wherever it comes from.
        for (i, &v) in a.iter().enumerate() {
            f32_finite("pose", &format!("row {} column {}", i / 4, i % 4), v)?;
        }
        let last = [a[12], a[13], a[14], a[15]];
        if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > RIGID_TOLERANCE {
            return Err(format!("pose's last row must be 0 0 0 1, got {last:?}"));
        }
        let r = self.rotation();
        let rtr = r.transpose() * r;
        let err = (rtr - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if err > RIGID_TOLERANCE {
            return Err(format!(
                "pose is not rigid: rotation part is not orthonormal (error {err:.2e})"
            ));
        }
        if r.determinant() < 0.0 {
            return Err("pose is not rigid: rotation part is a reflection (determinant < 0)".into());
        }
        Ok(())
    }
}

/// An axis-aligned box in world metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Bounds {
    pub fn check(&self) -> Result<(), String> {
        for i in 0..3 {
            if !self.min[i].is_finite() || !self.max[i].is_finite() {
                return Err(format!("bounds must be finite, got {self:?}"));
            }
            if self.min[i] >= self.max[i] {
                return Err(format!("bounds min must be below max on every axis, got {self:?}"));
            }
        }
        for i in 0..3 {
            let axis = ["x", "y", "z"][i];
            f32_finite("bounds", &format!("min.{axis}"), self.min[i])?;
            f32_finite("bounds", &format!("max.{axis}"), self.max[i])?;
            // Distinct in f64 but equal in f32 is an empty box on the GPU.
            if self.min[i] as f32 >= self.max[i] as f32 {
                return Err(format!(
                    "bounds min.{axis} = {} and max.{axis} = {} are equal as 32-bit floats; the box must have a size",
                    self.min[i], self.max[i]
                ));
            }
        }
        Ok(())
    }

    pub fn min_vec(&self) -> DVec3 {
        DVec3::from_array(self.min)
    }

    pub fn max_vec(&self) -> DVec3 {
        DVec3::from_array(self.max)
    }

    /// Smallest box holding all points, grown by `margin` (a fraction of its size) on each side.
    pub fn around(points: impl IntoIterator<Item = DVec3>, margin: f64) -> Option<Bounds> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut any = false;
        for p in points {
            lo = lo.min(p);
            hi = hi.max(p);
            any = true;
        }
        if !any {
            return None;
        }
        let pad = (hi - lo).max(DVec3::splat(1e-3)) * margin;
        Some(Bounds {
            min: (lo - pad).to_array(),
            max: (hi + pad).to_array(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_undoes_pose() {
        let p = Pose(DMat4::from_rotation_translation(
            glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0),
            DVec3::new(1.0, -2.0, 0.5),
        ));
        assert!(p.check().is_ok());
        let q = DVec3::new(0.2, 0.4, -3.0);
        let back = p.inverse().transform_point(p.transform_point(q));
        assert!((back - q).length() < 1e-12);
    }

    #[test]
    fn rejects_scaled_and_reflected_poses() {
        let scaled = Pose(DMat4::from_scale(DVec3::splat(2.0)));
        assert!(scaled.check().unwrap_err().contains("not rigid"));
        let mirrored = Pose(DMat4::from_scale(DVec3::new(1.0, 1.0, -1.0)));
        assert!(mirrored.check().unwrap_err().contains("reflection"));
        let mut nan = Pose::identity().to_row_major();
        nan[3] = f64::NAN;
        assert!(Pose::from_row_major(&nan).check().unwrap_err().contains("non-finite"));
    }

    #[test]
    fn opengl_conversion_flips_view_direction() {
        // An OpenGL camera at the origin looks down -z; in OpenCV axes its +z must point to -z.
        let p = Pose::from_opengl(DMat4::IDENTITY);
        assert_eq!(p.transform_vector(DVec3::Z), -DVec3::Z);
        assert_eq!(p.transform_vector(DVec3::Y), -DVec3::Y);
    }

    #[test]
    fn scaling_intrinsics_keeps_pixel_centres() {
        let k = Intrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: 319.5,
            cy: 239.5,
        };
        let half = k.scaled((640, 480), (320, 240));
        assert!((half.cx - 159.5).abs() < 1e-12 && (half.fx - 250.0).abs() < 1e-12);
    }
}
