//! Accumulation buffers: per-pixel, per-channel f64 sums.

use alloc::vec;
use alloc::vec::Vec;
use core::fmt;
use core::ops::AddAssign;
use serde::de::{DeserializeSeed, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::oracle::{Radiance, Resolution};

/// A `width x height` image with `channels` f64 values per pixel, row-major,
/// row 0 at the top.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Film {
    resolution: Resolution,
    channels: usize,
    data: Vec<f64>,
}

impl Film {
    /// A black film.
    pub fn new(resolution: Resolution, channels: usize) -> Self {
        Self {
            resolution,
            channels,
            data: vec![0.0; resolution.pixel_count() * channels],
        }
    }

    /// A black film, or [`Error::AllocationFailed`] if its memory (sized
    /// from the input) cannot be had.
    pub fn try_new(resolution: Resolution, channels: usize) -> Result<Self, Error> {
        let len = resolution.pixel_count().saturating_mul(channels);
        let bytes = (len as u64).saturating_mul(core::mem::size_of::<f64>() as u64);
        let mut data = Vec::new();
        data.try_reserve_exact(len)
            .map_err(|_| Error::AllocationFailed {
                what: "film",
                bytes,
            })?;
        data.resize(len, 0.0);
        Ok(Self {
            resolution,
            channels,
            data,
        })
    }

    /// Whether this film is `resolution` with `channels` channels, its values
    /// all there, finite and non-negative (a film read back from a
    /// checkpoint is checked: a forged one with a valid CRC resumed to NaN
    /// or negative pixels).
    pub fn fits(&self, resolution: Resolution, channels: usize) -> bool {
        self.resolution == resolution
            && self.channels == channels
            && self.data.len() == resolution.pixel_count() * channels
            && self.data.iter().all(|v| v.is_finite() && *v >= 0.0)
    }

    /// A film over existing values (`resolution.pixel_count() * channels` of them).
    pub fn from_data(
        resolution: Resolution,
        channels: usize,
        data: Vec<f64>,
    ) -> Result<Self, Error> {
        if channels == 0 || data.len() != resolution.pixel_count() * channels {
            return Err(Error::ShapeMismatch {
                left: (resolution.width, resolution.height, channels),
                right: (data.len() as u32, 1, 1),
            });
        }
        Ok(Self {
            resolution,
            channels,
            data,
        })
    }

    /// Size in pixels.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// Values per pixel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// All values, row-major, channels interleaved.
    pub fn data(&self) -> &[f64] {
        &self.data
    }

    /// All values, mutably.
    pub fn data_mut(&mut self) -> &mut [f64] {
        &mut self.data
    }

    /// The values of pixel `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> &[f64] {
        let i = (y as usize * self.resolution.width as usize + x as usize) * self.channels;
        &self.data[i..i + self.channels]
    }

    /// Adds `weight * radiance` to the pixel with index `pixel` (row-major).
    /// The radiance must have this film's channel count.
    #[inline]
    pub fn add<R: Radiance>(&mut self, pixel: usize, weight: f64, radiance: &R) {
        debug_assert_eq!(R::CHANNELS, self.channels);
        let base = pixel * self.channels;
        for (c, v) in self.data[base..base + self.channels].iter_mut().enumerate() {
            *v += weight * radiance.channel(c) as f64;
        }
    }

    /// Adds `other` pixel by pixel.
    pub fn merge(&mut self, other: &Film) -> Result<(), Error> {
        self.check_shape(other)?;
        self.data
            .iter_mut()
            .zip(&other.data)
            .for_each(|(a, b)| *a += b);
        Ok(())
    }

    /// Adds `s ·` `other`, a film of the same size and channels.
    pub(crate) fn add_scaled(&mut self, other: &Film, s: f64) {
        debug_assert_eq!(self.data.len(), other.data.len());
        for (v, o) in self.data.iter_mut().zip(&other.data) {
            *v += s * o;
        }
    }

    /// Multiplies every value by `s`.
    pub fn scale(&mut self, s: f64) {
        self.data.iter_mut().for_each(|v| *v *= s);
    }

    /// A copy multiplied by `s`.
    pub fn scaled(&self, s: f64) -> Film {
        let mut f = self.clone();
        f.scale(s);
        f
    }

    /// Luminance of pixel `index` (Rec. 709 for three channels, the value
    /// itself for one, the mean otherwise).
    pub fn luminance(&self, index: usize) -> f64 {
        let p = &self.data[index * self.channels..(index + 1) * self.channels];
        match p {
            [v] => *v,
            [r, g, b] => 0.2126 * r + 0.7152 * g + 0.0722 * b,
            _ => p.iter().sum::<f64>() / p.len() as f64,
        }
    }

    /// Mean of every value of channel `c` (a film's "total" in image units).
    pub fn channel_mean(&self, c: usize) -> f64 {
        self.data.iter().skip(c).step_by(self.channels).sum::<f64>()
            / self.resolution.pixel_count() as f64
    }

    pub(crate) fn check_shape(&self, other: &Film) -> Result<(), Error> {
        check_shapes(
            (self.resolution, self.channels),
            (other.resolution, other.channels),
        )
    }
}

/// [`Error::ShapeMismatch`] unless the two (resolution, channels) agree.
pub(crate) fn check_shapes(
    (a, a_channels): (Resolution, usize),
    (b, b_channels): (Resolution, usize),
) -> Result<(), Error> {
    if a != b || a_channels != b_channels {
        return Err(Error::ShapeMismatch {
            left: (a.width, a.height, a_channels),
            right: (b.width, b.height, b_channels),
        });
    }
    Ok(())
}

/// Adds a serialized [`Film`] of the film's shape to it as it is decoded,
/// value by value (a merge pooling runs holds the pooled film, not the
/// next); its value is whether the decoded film fits (its shape, and values
/// finite and non-negative, as [`Film::fits`]).
pub(crate) struct AddFilm<'a>(pub &'a mut Film);

impl<'de> DeserializeSeed<'de> for AddFilm<'_> {
    type Value = bool;
    fn deserialize<D: Deserializer<'de>>(self, decoder: D) -> Result<bool, D::Error> {
        const FIELDS: &[&str] = &["resolution", "channels", "data"];
        decoder.deserialize_struct("Film", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for AddFilm<'_> {
    type Value = bool;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a film")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut fields: A) -> Result<bool, A::Error> {
        let resolution: Option<Resolution> = fields.next_element()?;
        let channels: Option<usize> = fields.next_element()?;
        if resolution != Some(self.0.resolution) || channels != Some(self.0.channels) {
            return Ok(false);
        }
        let values = AddValues {
            into: &mut self.0.data,
            fits: |v: &f64| v.is_finite() && *v >= 0.0,
        };
        Ok(fields.next_element_seed(values)?.unwrap_or(false))
    }
}

/// Adds a serialized sequence of values to `into`, value by value, as it
/// is decoded; its value is whether there were as many and each `fits`.
pub(crate) struct AddValues<'a, T> {
    pub into: &'a mut [T],
    pub fits: fn(&T) -> bool,
}

impl<'de, T: Deserialize<'de> + AddAssign> DeserializeSeed<'de> for AddValues<'_, T> {
    type Value = bool;
    fn deserialize<D: Deserializer<'de>>(self, decoder: D) -> Result<bool, D::Error> {
        decoder.deserialize_seq(self)
    }
}

impl<'de, T: Deserialize<'de> + AddAssign> Visitor<'de> for AddValues<'_, T> {
    type Value = bool;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} values", self.into.len())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut values: A) -> Result<bool, A::Error> {
        let (mut into, mut fits) = (self.into.iter_mut(), true);
        while let Some(value) = values.next_element::<T>()? {
            match into.next() {
                Some(sum) if (self.fits)(&value) => *sum += value,
                _ => fits = false,
            }
        }
        Ok(fits && into.next().is_none())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Rgb;

    #[test]
    fn add_merge_scale() {
        let r = Resolution::new(2, 2);
        let mut a = Film::new(r, 3);
        a.add(3, 2.0, &Rgb([1.0, 2.0, 3.0]));
        assert_eq!(a.pixel(1, 1), &[2.0, 4.0, 6.0]);
        let mut b = Film::new(r, 3);
        b.add(3, 1.0, &Rgb([1.0, 1.0, 1.0]));
        b.merge(&a).unwrap();
        assert_eq!(b.scaled(0.5).pixel(1, 1), &[1.5, 2.5, 3.5]);
        assert!(b.merge(&Film::new(r, 1)).is_err());
        assert!(Film::from_data(r, 3, alloc::vec![0.0; 5]).is_err());
        let huge = Film::try_new(Resolution::new(u32::MAX, u32::MAX), 3);
        assert!(matches!(
            huge,
            Err(Error::AllocationFailed { what: "film", .. })
        ));
    }
}
