//! PLY meshes (ASCII, binary little- and big-endian): positions, optional
//! normals and texture coordinates, polygon faces (fan-triangulated).
//!
//! Read here, not by a crate: `ply-rs` (last released as 0.1.3) and its
//! maintained fork `ply-rs-bw` hold every vertex as a map of its named
//! properties, and the fork reserves each element's count from the header
//! before reading it (`Vec::with_capacity(count)`), so a header declaring
//! four billion vertices aborts the process. This reader grows what it
//! keeps only as the file's bytes are read, so a count the bytes do not
//! back ends in a typed error, and keeps positions, normals and texture
//! coordinates as flat arrays.

use std::path::Path;

use glam::{Vec2, Vec3};

use crate::SceneError;
use crate::scene::Mesh;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    LittleEndian,
    BigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Reads values in the file's format.
struct Reader<'a> {
    format: Format,
    bytes: &'a [u8],
    at: usize,
    /// ASCII tokens and the current one.
    tokens: Vec<&'a str>,
    token: usize,
}

impl Reader<'_> {
    fn read(&mut self, s: Scalar) -> Option<f64> {
        if self.format == Format::Ascii {
            let t = self.tokens.get(self.token)?;
            self.token += 1;
            return t.parse().ok();
        }
        let raw = self.bytes.get(self.at..self.at + s.size())?;
        self.at += s.size();
        let le = self.format == Format::LittleEndian;
        macro_rules! num {
            ($t:ty) => {{
                let a = raw.try_into().ok()?;
                (if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }) as f64
            }};
        }
        Some(match s {
            Scalar::I8 => raw[0] as i8 as f64,
            Scalar::U8 => raw[0] as f64,
            Scalar::I16 => num!(i16),
            Scalar::U16 => num!(u16),
            Scalar::I32 => num!(i32),
            Scalar::U32 => num!(u32),
            Scalar::F32 => num!(f32),
            Scalar::F64 => num!(f64),
        })
    }
}

/// Reads the PLY file at `path`.
pub fn read(path: &Path) -> Result<Mesh, SceneError> {
    let bytes = crate::input::read(path)?;
    parse(&bytes).map_err(|(line, message)| SceneError::at(path, line, message))
}

/// Parses PLY bytes; errors carry the header line (or 0 for the body).
pub fn parse(bytes: &[u8]) -> Result<Mesh, (usize, String)> {
    let header_end = find(bytes, b"end_header").ok_or((1, "no end_header".to_string()))?;
    let header = std::str::from_utf8(&bytes[..header_end])
        .map_err(|_| (1, "header is not text".to_string()))?;
    let mut body_start = header_end + "end_header".len();
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    body_start += 1;
    let mut lines = header.lines().enumerate();
    if lines.next().map(|(_, l)| l.trim()) != Some("ply") {
        return Err((1, "not a PLY file (first line is not `ply`)".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::LittleEndian,
                    "binary_big_endian" => Format::BigEndian,
                    other => return Err((line_no, format!("unknown PLY format `{other}`"))),
                })
            }
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| (line_no, format!("bad element count `{count}`")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, item, name] => {
                let (Some(c), Some(t)) = (Scalar::parse(count), Scalar::parse(item)) else {
                    return Err((line_no, format!("unknown list types `{count} {item}`")));
                };
                let e = elements
                    .last_mut()
                    .ok_or((line_no, "property before element".to_string()))?;
                e.properties.push(Property::List(name.to_string(), c, t));
            }
            ["property", ty, name] => {
                let t =
                    Scalar::parse(ty).ok_or((line_no, format!("unknown property type `{ty}`")))?;
                let e = elements
                    .last_mut()
                    .ok_or((line_no, "property before element".to_string()))?;
                e.properties.push(Property::Scalar(name.to_string(), t));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err((line_no, format!("unexpected header line `{line}`"))),
        }
    }
    let format = format.ok_or((1, "missing format line".to_string()))?;
    let body = &bytes[body_start.min(bytes.len())..];
    let tokens = if format == Format::Ascii {
        std::str::from_utf8(body)
            .map_err(|_| (0, "ASCII body is not text".to_string()))?
            .split_whitespace()
            .collect()
    } else {
        Vec::new()
    };
    let mut reader = Reader {
        format,
        bytes: body,
        at: 0,
        tokens,
        token: 0,
    };
    let truncated = || (0, "file ends before all elements were read".to_string());
    let mut mesh = Mesh::default();
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    // An element without properties holds no data, whatever its count
    // (counting to a hostile 10^19 would never end).
    for e in elements.iter().filter(|e| !e.properties.is_empty()) {
        for _ in 0..e.count {
            let mut v = [0.0f64; 8]; // x y z nx ny nz u v
            let mut seen = [false; 8];
            for p in &e.properties {
                match p {
                    Property::Scalar(name, t) => {
                        let value = reader.read(*t).ok_or_else(truncated)?;
                        let slot = match name.as_str() {
                            "x" => 0,
                            "y" => 1,
                            "z" => 2,
                            "nx" => 3,
                            "ny" => 4,
                            "nz" => 5,
                            "u" | "s" | "texture_u" | "texture_s" => 6,
                            "v" | "t" | "texture_v" | "texture_t" => 7,
                            _ => continue,
                        };
                        v[slot] = value;
                        seen[slot] = true;
                    }
                    Property::List(name, count_type, item_type) => {
                        let n = reader.read(*count_type).ok_or_else(truncated)? as usize;
                        let items: Vec<f64> = (0..n)
                            .map(|_| reader.read(*item_type))
                            .collect::<Option<_>>()
                            .ok_or_else(truncated)?;
                        if e.name == "face" && (name == "vertex_indices" || name == "vertex_index")
                        {
                            for k in 1..n.saturating_sub(1) {
                                let tri = [items[0], items[k], items[k + 1]];
                                if tri.iter().any(|&i| i < 0.0 || i >= u32::MAX as f64) {
                                    return Err((
                                        0,
                                        format!("negative or huge vertex index in face {tri:?}"),
                                    ));
                                }
                                mesh.indices.push(tri.map(|i| i as u32));
                            }
                        }
                    }
                }
            }
            if e.name == "vertex" {
                mesh.positions
                    .push(Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32));
                if seen[3] && seen[4] && seen[5] {
                    normals.push(Vec3::new(v[3] as f32, v[4] as f32, v[5] as f32));
                }
                if seen[6] && seen[7] {
                    uvs.push(Vec2::new(v[6] as f32, v[7] as f32));
                }
            }
        }
    }
    let left = if format == Format::Ascii {
        reader.tokens.len() - reader.token.min(reader.tokens.len())
    } else {
        let rest = &reader.bytes[reader.at.min(reader.bytes.len())..];
        rest.iter().filter(|b| !b.is_ascii_whitespace()).count()
    };
    if left > 0 {
        return Err((
            0,
            format!(
                "the file holds more data than its header declares ({left} {} left after the last element)",
                if format == Format::Ascii {
                    "values"
                } else {
                    "bytes"
                }
            ),
        ));
    }
    let n = mesh.positions.len();
    if let Some(bad) = mesh.indices.iter().flatten().find(|&&i| i as usize >= n) {
        return Err((0, format!("face refers to vertex {bad} of {n}")));
    }
    mesh.normals = (normals.len() == n && n > 0).then_some(normals);
    mesh.uvs = (uvs.len() == n && n > 0).then_some(uvs);
    Ok(mesh)
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment a quad\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";

    #[test]
    fn ascii_quad_is_fan_triangulated() {
        let m = parse(ASCII.as_bytes()).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uvs.unwrap()[2], Vec2::ONE);
        assert!(m.normals.is_none());
    }

    #[test]
    fn binary_matches_ascii() {
        let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
        for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            p.iter().for_each(|c| b.extend(c.to_be_bytes()));
        }
        b.push(3);
        [0u32, 1, 2].iter().for_each(|i| b.extend(i.to_be_bytes()));
        let m = parse(&b).unwrap();
        assert_eq!(m.positions[1], Vec3::X);
        assert_eq!(m.indices, vec![[0, 1, 2]]);
        b.extend([0u8; 12]);
        assert!(parse(&b).unwrap_err().1.contains("12 bytes left"));
    }

    #[test]
    fn malformed_files_are_errors_with_lines() {
        assert_eq!(parse(b"plx\nend_header\n").unwrap_err().0, 1);
        let bad_type = ASCII.replace("property float y", "property quux y");
        assert_eq!(parse(bad_type.as_bytes()).unwrap_err().0, 6);
        let truncated = &ASCII[..ASCII.len() - 8];
        assert!(
            parse(truncated.as_bytes())
                .unwrap_err()
                .1
                .contains("ends before")
        );
        let out_of_range = ASCII.replace("4 0 1 2 3", "3 0 1 9");
        assert!(
            parse(out_of_range.as_bytes())
                .unwrap_err()
                .1
                .contains("vertex 9")
        );
        assert!(parse(b"").is_err());
        // A header that declares fewer elements than the file holds.
        let fewer = ASCII.replace("element vertex 4", "element vertex 3");
        let e = parse(fewer.as_bytes()).unwrap_err().1;
        assert!(e.contains("more data than its header declares"), "{e}");
    }

    /// Nothing is reserved from a header's counts: four billion vertices
    /// declared over a few bytes end where the bytes do, in a typed error.
    #[test]
    fn counts_the_bytes_do_not_back_are_errors_not_allocations() {
        for count in ["4000000000", "18446744073709551615"] {
            let huge = ASCII.replace("element vertex 4", &format!("element vertex {count}"));
            let e = parse(huge.as_bytes()).unwrap_err().1;
            assert!(e.contains("ends before"), "{count}: {e}");
        }
        let list = ASCII.replace("4 0 1 2 3", "4294967295 0 1 2 3");
        let list = list.replace("list uchar int", "list uint int");
        assert!(
            parse(list.as_bytes())
                .unwrap_err()
                .1
                .contains("ends before")
        );
    }
}
