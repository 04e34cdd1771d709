//! Overlapping tiles of stratified MCMC (Gruson et al. 2020, sec. 3, fig. 3): one tile
//! per pixel, centred on it, clipped at the image border.
//!
//! The default tile is the cross of the pixel and its four neighbours, "the
//! simplest and smallest domain that still has uniform overlap with its
//! neighbours in all directions"; square tiles (`(2r+1)²` pixels) are the
//! other shape Gruson et al. 2020 leaves for future work. Tile `s` is centred on pixel
//! `s`; its pixels are `s + offset` for every offset that stays on the film.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::oracle::Resolution;

/// The shape of every tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[non_exhaustive]
pub enum TileShape {
    /// The pixel and its 4 neighbours (Gruson et al.'s (2020) choice).
    #[default]
    Cross,
    /// The `(2 radius + 1)²` pixels around the centre.
    Square {
        /// Pixels from the centre to the edge (1 gives 3x3).
        radius: u32,
    },
}

impl TileShape {
    /// Checks the shape's parameters (a square's radius is 1 to 16).
    pub fn validate(&self) -> Result<(), Error> {
        match *self {
            TileShape::Square { radius } if radius == 0 || radius > 16 => Err(Error::invalid(
                "radius",
                radius as f64,
                "a square tile radius between 1 and 16",
            )),
            _ => Ok(()),
        }
    }
}

/// The tiles of a film.
#[derive(Clone, Debug, PartialEq)]
pub struct Tiles {
    resolution: Resolution,
    /// Offsets `(dx, dy)`, the centre `(0, 0)` first.
    offsets: Vec<(i32, i32)>,
}

impl Tiles {
    /// One tile per pixel of `resolution`, of shape `shape`.
    pub fn new(resolution: Resolution, shape: TileShape) -> Result<Self, Error> {
        if resolution.pixel_count() == 0 {
            return Err(Error::EmptyResolution);
        }
        shape.validate()?;
        let offsets = match shape {
            TileShape::Cross => alloc::vec![(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)],
            TileShape::Square { radius } => {
                let r = radius as i32;
                let mut o = alloc::vec![(0, 0)];
                for dy in -r..=r {
                    for dx in -r..=r {
                        if (dx, dy) != (0, 0) {
                            o.push((dx, dy));
                        }
                    }
                }
                o
            }
        };
        Ok(Self {
            resolution,
            offsets,
        })
    }

    /// The film.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// Number of tiles (= pixels).
    pub fn count(&self) -> usize {
        self.resolution.pixel_count()
    }

    /// How many rows a tile reaches above and below its centre.
    pub fn reach(&self) -> usize {
        self.offsets
            .iter()
            .map(|&(_, dy)| dy.unsigned_abs() as usize)
            .max()
            .unwrap_or(0)
    }

    /// The offsets of a tile's pixels from its centre, the centre first.
    pub fn offsets(&self) -> &[(i32, i32)] {
        &self.offsets
    }

    /// The pixel of tile `tile` at offset `offset`, or `None` where the tile
    /// is clipped by the border.
    #[inline]
    pub fn pixel(&self, tile: usize, offset: usize) -> Option<usize> {
        let w = self.resolution.width as i64;
        let h = self.resolution.height as i64;
        let (x, y) = ((tile as i64) % w, (tile as i64) / w);
        let (dx, dy) = self.offsets[offset];
        let (px, py) = (x + dx as i64, y + dy as i64);
        (px >= 0 && py >= 0 && px < w && py < h).then(|| (py * w + px) as usize)
    }

    /// `(offset, pixel)` of every pixel of tile `tile`.
    pub fn pixels(&self, tile: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.offsets.len()).filter_map(move |o| self.pixel(tile, o).map(|p| (o, p)))
    }

    /// The offset at which tile `tile` contains pixel `pixel`, if it does.
    pub(crate) fn offset_of(&self, tile: usize, pixel: usize) -> Option<usize> {
        (0..self.offsets.len()).find(|&o| self.pixel(tile, o) == Some(pixel))
    }

    /// `(tile, offset)` of every tile containing pixel `pixel` (offsets are
    /// symmetric, so the tiles are `pixel - offset`).
    pub fn tiles_of(&self, pixel: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let w = self.resolution.width as i64;
        let h = self.resolution.height as i64;
        let (x, y) = ((pixel as i64) % w, (pixel as i64) / w);
        self.offsets
            .iter()
            .enumerate()
            .filter_map(move |(o, &(dx, dy))| {
                let (tx, ty) = (x - dx as i64, y - dy as i64);
                (tx >= 0 && ty >= 0 && tx < w && ty < h).then(|| ((ty * w + tx) as usize, o))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::FilmPoint;

    #[test]
    fn tiles_are_clipped_crosses_and_cover_each_pixel_as_often_as_they_overlap_it() {
        let t = Tiles::new(Resolution::new(5, 3), TileShape::Cross).unwrap();
        assert_eq!(t.pixels(0).count(), 3); // corner: centre, right, down
        assert_eq!(t.pixels(7).count(), 5); // interior
        for p in 0..t.count() {
            let containing: Vec<(usize, usize)> = t.tiles_of(p).collect();
            // Pixel p is in tile s at offset o exactly when tile s lists it there.
            for &(s, o) in &containing {
                assert_eq!(t.pixel(s, o), Some(p));
            }
            let listed = (0..t.count())
                .flat_map(|s| t.pixels(s).map(move |(_, q)| (s, q)))
                .filter(|&(_, q)| q == p)
                .count();
            assert_eq!(listed, containing.len());
        }
        let square = Tiles::new(Resolution::new(4, 4), TileShape::Square { radius: 1 }).unwrap();
        assert_eq!(square.pixels(5).count(), 9);
        assert!(Tiles::new(Resolution::new(0, 4), TileShape::Cross).is_err());
        assert_eq!(t.offset_of(7, 8), Some(1));
        assert_eq!(t.offset_of(7, 9), None);
        let wide = Tiles::new(Resolution::new(40_000, 2), TileShape::Cross).unwrap();
        let almost_one = f32::from_bits(1.0f32.to_bits() - 1);
        let p = wide.resolution().pixel_point(
            39_999,
            FilmPoint {
                x: almost_one,
                y: 0.5,
            },
        );
        assert!(p.x < 40_000.0 && p.x >= 39_999.0);
        assert!(Tiles::new(Resolution::new(4, 4), TileShape::Square { radius: 0 }).is_err());
    }
}
