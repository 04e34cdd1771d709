//! Spatially varying colors.

use glam::{Vec2, Vec3};

/// A spatially varying color.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// One color everywhere.
    Constant(Vec3),
    /// An image, linear RGB, row 0 at the top, repeated outside `[0, 1]`.
    Image {
        /// Width in texels.
        width: u32,
        /// Height in texels.
        height: u32,
        /// Linear RGB texels.
        texels: Vec<Vec3>,
        /// `(u, v)` scale.
        scale: Vec2,
    },
    /// Two colors in a checkerboard of `scale` checks per unit of `(u, v)`.
    Checkerboard {
        /// Color of even checks.
        even: Vec3,
        /// Color of odd checks.
        odd: Vec3,
        /// Checks per unit.
        scale: Vec2,
    },
}

impl Texture {
    /// The color at texture coordinates `uv` (bilinear for images).
    pub fn eval(&self, uv: Vec2) -> Vec3 {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { even, odd, scale } => {
                let p = uv * *scale;
                if (p.x.floor() as i64 + p.y.floor() as i64) % 2 == 0 {
                    *even
                } else {
                    *odd
                }
            }
            Texture::Image {
                width,
                height,
                texels,
                scale,
            } => {
                let (w, h) = (*width as i64, *height as i64);
                // pbrt's v points up the image.
                let p = uv * *scale;
                let x = p.x * w as f32 - 0.5;
                let y = (1.0 - p.y) * h as f32 - 0.5;
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let texel =
                    |i: i64, j: i64| texels[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
                let (i, j) = (x0 as i64, y0 as i64);
                texel(i, j) * (1.0 - fx) * (1.0 - fy)
                    + texel(i + 1, j) * fx * (1.0 - fy)
                    + texel(i, j + 1) * (1.0 - fx) * fy
                    + texel(i + 1, j + 1) * fx * fy
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures() {
        let check = Texture::Checkerboard {
            even: Vec3::ZERO,
            odd: Vec3::ONE,
            scale: Vec2::splat(2.0),
        };
        assert_eq!(check.eval(Vec2::new(0.1, 0.1)), Vec3::ZERO);
        assert_eq!(check.eval(Vec2::new(0.6, 0.1)), Vec3::ONE);
        let img = Texture::Image {
            width: 2,
            height: 1,
            texels: vec![Vec3::ZERO, Vec3::ONE],
            scale: Vec2::ONE,
        };
        assert!((img.eval(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
    }
}
