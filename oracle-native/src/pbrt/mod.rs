//! The subset of pbrt-v3's scene format that Bitterli's scenes use.
//!
//! Directives: `Camera "perspective"` (fov), `Film` (resolution),
//! `Integrator` (maxdepth), `Transform`, `ConcatTransform`, `LookAt`,
//! `Translate`, `Scale`, `Rotate`, `Identity`, `WorldBegin/End`,
//! `AttributeBegin/End`, `TransformBegin/End`, `Shape` (`trianglemesh`,
//! `plymesh`), `MakeNamedMaterial`, `NamedMaterial`, `Material` (`matte`,
//! `metal`, `glass`, `mirror`, `plastic`, with `remaproughness`), `Texture`
//! (`imagemap`, sRGB decoded to linear, and `checkerboard`),
//! `AreaLightSource "diffuse"`, `LightSource "infinite"` (constant).
//! Anything else is skipped and reported once by name in [`Loaded::ignored`];
//! malformed input is a [`SceneError`] naming the file and line.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec2, Vec3};
use strata_engine::Resolution;

use crate::material::{ConductorFresnel, Material, Texture, roughness_to_alpha};
use crate::scene::{Camera, MAX_COORDINATE, Mesh, Scene};
use crate::{SceneError, ply};

mod syntax;
use syntax::{Params, Token, Value, tokenize};

/// Where the real test scenes live: `$STRATA_SCENES` if set, else the
/// repository's `scenes/` (Bitterli's Cornell box with Tungsten's
/// reference, and veach-ajar; CC0, with their licence files), found from
/// this crate's source directory whatever the working directory.
pub fn scenes_dir() -> PathBuf {
    std::env::var_os("STRATA_SCENES").map_or_else(
        || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes")),
        PathBuf::from,
    )
}

/// Loads `name/scene.pbrt` from [`scenes_dir`].
pub fn load_shared(name: &str) -> Result<Loaded, SceneError> {
    load(&scenes_dir().join(name).join("scene.pbrt"))
}

/// A loaded scene and what the loader skipped.
#[derive(Debug)]
pub struct Loaded {
    /// The scene.
    pub scene: Scene,
    /// Directives and types that were not understood (each named once).
    pub ignored: BTreeSet<String>,
}

/// Loads a pbrt-v3 file; relative paths inside resolve from its directory.
pub fn load(path: &Path) -> Result<Loaded, SceneError> {
    let text = crate::input::read_text(path)?;
    parse(&text, path)
}

/// Parses pbrt-v3 scene text as if read from `path`: relative paths inside
/// resolve from its directory, and errors name it.
pub fn parse(text: &str, path: &Path) -> Result<Loaded, SceneError> {
    let tokens = tokenize(text).map_err(|(line, m)| SceneError::at(path, line, m))?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    Parser {
        path: path.to_path_buf(),
        dir,
        tokens,
        at: 0,
        state: State::default(),
        out: Output::default(),
    }
    .run()
}

#[derive(Clone, Debug, Default)]
struct State {
    ctm: Mat4,
    material: Option<u32>,
    emission: Option<Vec3>,
}

#[derive(Default)]
struct Output {
    camera_from_world: Option<Mat4>,
    fov: f32,
    resolution: Option<Resolution>,
    max_depth: Option<u32>,
    materials: Vec<Material>,
    named: HashMap<String, u32>,
    textures: HashMap<String, Texture>,
    meshes: Vec<(Mesh, u32, Option<Vec3>)>,
    environment: Option<Vec3>,
    ignored: BTreeSet<String>,
}

struct Parser {
    path: PathBuf,
    dir: PathBuf,
    tokens: Vec<(Token, usize)>,
    at: usize,
    state: State,
    out: Output,
}

impl Parser {
    fn err<T>(&self, message: impl Into<String>) -> Result<T, SceneError> {
        Err(SceneError::at(&self.path, self.line(), message.into()))
    }

    fn next(&mut self) -> Option<Token> {
        let t = self.tokens.get(self.at).map(|t| t.0.clone());
        self.at += 1;
        t
    }

    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.at).map(|t| &t.0)
    }

    fn string(&mut self) -> Result<String, SceneError> {
        match self.next() {
            Some(Token::Str(s)) => Ok(s),
            other => self.err(format!("expected a quoted string, found {other:?}")),
        }
    }

    /// `n` numbers, bare or in brackets.
    fn numbers(&mut self, n: usize) -> Result<Vec<f64>, SceneError> {
        let bracketed = self.peek() == Some(&Token::Open);
        if bracketed {
            self.next();
        }
        let mut v = Vec::with_capacity(n);
        for _ in 0..n {
            match self.next() {
                Some(Token::Num(x)) => v.push(x),
                other => return self.err(format!("expected {n} numbers, found {other:?}")),
            }
        }
        if bracketed && self.next() != Some(Token::Close) {
            return self.err("expected `]`");
        }
        Ok(v)
    }

    fn params(&mut self) -> Result<Params, SceneError> {
        let mut p = Params::default();
        while let Some(Token::Str(decl)) = self.peek().cloned() {
            self.next();
            let mut words = decl.split_whitespace();
            let (Some(ty), Some(name), None) = (words.next(), words.next(), words.next()) else {
                return self.err(format!("bad parameter declaration `{decl}`"));
            };
            let value = match self.next() {
                Some(Token::Open) => {
                    let (mut nums, mut strs) = (Vec::new(), Vec::new());
                    loop {
                        match self.next() {
                            Some(Token::Close) => break,
                            Some(Token::Num(x)) => nums.push(x),
                            Some(Token::Str(s)) => strs.push(s),
                            Some(Token::Word(w)) if w == "true" || w == "false" => strs.push(w),
                            other => {
                                return self
                                    .err(format!("unexpected {other:?} in parameter `{name}`"));
                            }
                        }
                    }
                    if strs.is_empty() {
                        Value::Nums(nums)
                    } else {
                        Value::Strs(strs)
                    }
                }
                Some(Token::Num(x)) => Value::Nums(vec![x]),
                Some(Token::Str(s)) => Value::Strs(vec![s]),
                Some(Token::Word(w)) if w == "true" || w == "false" => Value::Strs(vec![w]),
                other => return self.err(format!("parameter `{name}` has no value ({other:?})")),
            };
            p.0.insert(name.to_string(), (ty.to_string(), value));
        }
        Ok(p)
    }

    fn run(mut self) -> Result<Loaded, SceneError> {
        let mut stack: Vec<State> = Vec::new();
        let mut transform_stack: Vec<Mat4> = Vec::new();
        while let Some(token) = self.next() {
            let Token::Word(directive) = token else {
                return self.err(format!("expected a directive, found {token:?}"));
            };
            match directive.as_str() {
                "WorldBegin" => self.state.ctm = Mat4::IDENTITY,
                "WorldEnd" => {}
                "AttributeBegin" => stack.push(self.state.clone()),
                "AttributeEnd" => match stack.pop() {
                    Some(s) => self.state = s,
                    None => return self.err("AttributeEnd without AttributeBegin"),
                },
                "TransformBegin" => transform_stack.push(self.state.ctm),
                "TransformEnd" => match transform_stack.pop() {
                    Some(m) => self.state.ctm = m,
                    None => return self.err("TransformEnd without TransformBegin"),
                },
                "Identity" => self.state.ctm = Mat4::IDENTITY,
                "Transform" => {
                    let m = self.matrix()?;
                    self.set_transform(m)?;
                }
                "ConcatTransform" => {
                    let m = self.matrix()?;
                    self.set_transform(self.state.ctm * m)?;
                }
                "Translate" => {
                    let v = self.finite_numbers(3, "Translate")?;
                    self.set_transform(self.state.ctm * Mat4::from_translation(vec3(&v)))?;
                }
                "Scale" => {
                    let v = self.finite_numbers(3, "Scale")?;
                    if v.contains(&0.0) {
                        return self.err(format!("Scale by zero ({v:?}) flattens the scene"));
                    }
                    self.set_transform(self.state.ctm * Mat4::from_scale(vec3(&v)))?;
                }
                "Rotate" => {
                    let v = self.finite_numbers(4, "Rotate")?;
                    let axis = vec3(&v[1..]).normalize_or_zero();
                    if axis == Vec3::ZERO {
                        return self.err("Rotate about a zero axis");
                    }
                    let r = Mat4::from_axis_angle(axis, (v[0] as f32).to_radians());
                    self.set_transform(self.state.ctm * r)?;
                }
                "LookAt" => {
                    let v = self.finite_numbers(9, "LookAt")?;
                    let m = self.look_at(vec3(&v[0..3]), vec3(&v[3..6]), vec3(&v[6..9]))?;
                    self.set_transform(self.state.ctm * m)?;
                }
                "Camera" => {
                    let ty = self.string()?;
                    let p = self.params()?;
                    if ty != "perspective" {
                        self.out
                            .ignored
                            .insert(format!("Camera \"{ty}\" (treated as perspective)"));
                    }
                    self.out.camera_from_world = Some(self.state.ctm);
                    let fov = p.num("fov").unwrap_or(90.0);
                    if !(fov > 0.0 && fov < 180.0) {
                        return self.err(format!("fov must be in (0, 180) degrees, got {fov}"));
                    }
                    self.out.fov = fov as f32;
                }
                "Film" => {
                    let _ = self.string()?;
                    let p = self.params()?;
                    let w = self.whole(&p, "xresolution", 640, 1..=MAX_FILM_SIDE)?;
                    let h = self.whole(&p, "yresolution", 480, 1..=MAX_FILM_SIDE)?;
                    self.out.resolution = Some(Resolution::new(w, h));
                }
                "Integrator" => {
                    let _ = self.string()?;
                    let p = self.params()?;
                    if p.num("maxdepth").is_some() {
                        self.out.max_depth = Some(self.whole(&p, "maxdepth", 16, 1..=1024)?);
                    }
                }
                "Sampler" | "PixelFilter" | "Accelerator" | "SurfaceIntegrator" => {
                    let _ = self.string()?;
                    let _ = self.params()?;
                    self.out
                        .ignored
                        .insert(format!("{directive} (the engine chooses)"));
                }
                "Texture" => self.texture()?,
                "MakeNamedMaterial" => {
                    let name = self.string()?;
                    let p = self.params()?;
                    let ty = p.string("type").unwrap_or("matte").to_string();
                    let m = self.material(&ty, &p)?;
                    self.out.materials.push(m);
                    self.out
                        .named
                        .insert(name, self.out.materials.len() as u32 - 1);
                }
                "NamedMaterial" => {
                    let name = self.string()?;
                    match self.out.named.get(&name) {
                        Some(&i) => self.state.material = Some(i),
                        None => return self.err(format!("unknown material `{name}`")),
                    }
                }
                "Material" => {
                    let ty = self.string()?;
                    let p = self.params()?;
                    let m = self.material(&ty, &p)?;
                    self.out.materials.push(m);
                    self.state.material = Some(self.out.materials.len() as u32 - 1);
                }
                "AreaLightSource" => {
                    let ty = self.string()?;
                    let p = self.params()?;
                    if ty != "diffuse" {
                        self.out.ignored.insert(format!("AreaLightSource \"{ty}\""));
                    }
                    let l = p.rgb("L").unwrap_or(Vec3::ONE) * p.rgb("scale").unwrap_or(Vec3::ONE);
                    self.state.emission = Some(self.checked_color(l, "L")?);
                }
                "LightSource" => {
                    let ty = self.string()?;
                    let p = self.params()?;
                    if ty == "infinite" && p.string("mapname").is_none() {
                        let l =
                            p.rgb("L").unwrap_or(Vec3::ONE) * p.rgb("scale").unwrap_or(Vec3::ONE);
                        self.out.environment = Some(self.checked_color(l, "L")?);
                    } else {
                        self.out.ignored.insert(format!("LightSource \"{ty}\""));
                    }
                }
                "Shape" => self.shape()?,
                other => {
                    // Skip an unknown directive's arguments.
                    while matches!(
                        self.peek(),
                        Some(Token::Str(_) | Token::Num(_) | Token::Open | Token::Close)
                    ) {
                        self.next();
                    }
                    self.out.ignored.insert(other.to_string());
                }
            }
        }
        self.finish()
    }

    /// `n` numbers (see [`numbers`](Self::numbers)), all finite.
    fn finite_numbers(&mut self, n: usize, directive: &str) -> Result<Vec<f64>, SceneError> {
        let v = self.numbers(n)?;
        if v.iter().any(|x| !x.is_finite()) {
            return self.err(format!("{directive} needs finite numbers, got {v:?}"));
        }
        Ok(v)
    }

    /// Makes `m` the current transform: finite and invertible (a singular
    /// transform flattens what follows; a huge one overflows f32).
    fn set_transform(&mut self, m: Mat4) -> Result<(), SceneError> {
        let det = m.determinant();
        if !(m.is_finite() && det.is_finite() && det != 0.0 && m.inverse().is_finite()) {
            return self.err(format!(
                "the transform becomes singular or non-finite (determinant {det})"
            ));
        }
        self.state.ctm = m;
        Ok(())
    }

    /// Integer parameter `name` (or `default`): a whole number in `range`.
    fn whole(
        &self,
        p: &Params,
        name: &str,
        default: u32,
        range: std::ops::RangeInclusive<u32>,
    ) -> Result<u32, SceneError> {
        let Some(v) = p.num(name) else {
            return Ok(default);
        };
        let (lo, hi) = (*range.start() as f64, *range.end() as f64);
        if !(v.fract() == 0.0 && v >= lo && v <= hi) {
            return self.err(format!(
                "`{name}` must be a whole number in {lo}..={hi}, got {v}"
            ));
        }
        Ok(v as u32)
    }

    fn matrix(&mut self) -> Result<Mat4, SceneError> {
        let v = self.numbers(16)?;
        let a: [f32; 16] = std::array::from_fn(|i| v[i] as f32);
        // pbrt lists the matrix transposed, i.e. column by column.
        let m = Mat4::from_cols_array(&a);
        if !m.is_finite() {
            return self.err("non-finite transform");
        }
        Ok(m)
    }

    /// pbrt's (left-handed) `LookAt`: a world-to-camera matrix.
    fn look_at(&self, eye: Vec3, target: Vec3, up: Vec3) -> Result<Mat4, SceneError> {
        let dir = (target - eye).normalize_or_zero();
        let right = up.normalize_or_zero().cross(dir).normalize_or_zero();
        if dir == Vec3::ZERO || right == Vec3::ZERO {
            return self.err("degenerate LookAt");
        }
        let new_up = dir.cross(right);
        Ok(Mat4::from_cols(
            right.extend(0.0),
            new_up.extend(0.0),
            dir.extend(0.0),
            eye.extend(1.0),
        )
        .inverse())
    }

    fn checked_color(&self, c: Vec3, name: &str) -> Result<Vec3, SceneError> {
        if c.is_finite() && c.min_element() >= 0.0 {
            Ok(c)
        } else {
            self.err(format!("`{name}` must be finite and >= 0, got {c}"))
        }
    }

    fn color_or_texture(
        &self,
        p: &Params,
        name: &str,
        default: Vec3,
    ) -> Result<Texture, SceneError> {
        if p.ty(name) == Some("texture") {
            let t = p.string(name).unwrap_or_default();
            return match self.out.textures.get(t) {
                Some(tex) => Ok(tex.clone()),
                None => self.err(format!("unknown texture `{t}`")),
            };
        }
        Ok(Texture::Constant(
            self.checked_color(p.rgb(name).unwrap_or(default), name)?,
        ))
    }

    /// A microfacet alpha from `roughness` (or `uroughness`), remapped as
    /// pbrt-v3 does unless `remaproughness` is false; 0 stays 0 (smooth)
    /// where `zero_is_smooth`, as for pbrt-v3's glass (`GlassMaterial`'s
    /// `isSpecular`, tested before the remapping, which takes 0 to 0.045).
    fn roughness(&self, p: &Params, default: f64, zero_is_smooth: bool) -> Result<f32, SceneError> {
        let r = p
            .num("roughness")
            .or_else(|| p.num("uroughness"))
            .unwrap_or(default);
        if !(r.is_finite() && r >= 0.0) {
            return self.err(format!("roughness must be finite and >= 0, got {r}"));
        }
        let remap = p.bool("remaproughness").unwrap_or(true);
        let alpha = if remap && !(zero_is_smooth && r == 0.0) {
            roughness_to_alpha(r as f32)
        } else {
            r as f32
        };
        Ok(alpha.clamp(0.0, 1.0))
    }

    fn material(&mut self, ty: &str, p: &Params) -> Result<Material, SceneError> {
        Ok(match ty {
            "matte" => Material::Diffuse {
                reflectance: self.color_or_texture(p, "Kd", Vec3::splat(0.5))?,
            },
            "metal" => {
                // pbrt-v3's defaults: copper.
                let eta = p.rgb("eta").unwrap_or(Vec3::new(0.2004, 0.9240, 1.1022));
                let k = p.rgb("k").unwrap_or(Vec3::new(3.9129, 2.4528, 2.1421));
                Material::Conductor {
                    fresnel: ConductorFresnel::Complex {
                        eta: self.checked_color(eta, "eta")?,
                        k: self.checked_color(k, "k")?,
                    },
                    alpha: self.roughness(p, 0.01, false)?,
                }
            }
            "glass" => {
                let eta = p.num("index").or_else(|| p.num("eta")).unwrap_or(1.5) as f32;
                if !(eta.is_finite() && eta > 0.0) {
                    return self.err(format!("glass index must be > 0, got {eta}"));
                }
                Material::Dielectric {
                    eta,
                    alpha: self.roughness(p, 0.0, true)?,
                }
            }
            "mirror" => Material::Conductor {
                fresnel: ConductorFresnel::Constant(
                    self.checked_color(p.rgb("Kr").unwrap_or(Vec3::splat(0.9)), "Kr")?,
                ),
                alpha: 0.0,
            },
            "plastic" => Material::Plastic {
                diffuse: self.color_or_texture(p, "Kd", Vec3::splat(0.25))?,
                specular: self.checked_color(p.rgb("Ks").unwrap_or(Vec3::splat(0.25)), "Ks")?,
                alpha: self.roughness(p, 0.1, false)?.max(1e-3),
            },
            other => {
                self.out
                    .ignored
                    .insert(format!("material \"{other}\" (rendered as matte)"));
                Material::Diffuse {
                    reflectance: Texture::Constant(Vec3::splat(0.5)),
                }
            }
        })
    }

    fn texture(&mut self) -> Result<(), SceneError> {
        let name = self.string()?;
        let _kind = self.string()?;
        let class = self.string()?;
        let p = self.params()?;
        let (u, v) = (
            p.num("uscale").unwrap_or(1.0),
            p.num("vscale").unwrap_or(1.0),
        );
        if !(u.is_finite() && v.is_finite() && u != 0.0 && v != 0.0) {
            return self.err(format!(
                "texture scales must be finite and non-zero, got {u}, {v}"
            ));
        }
        let scale = Vec2::new(u as f32, v as f32);
        let tex = match class.as_str() {
            "imagemap" => {
                let file = p.string("filename").unwrap_or_default();
                let path = self.dir.join(file);
                let img = crate::input::read_image(&path).map_err(|e| {
                    SceneError::at(
                        &self.path,
                        self.line(),
                        format!("texture {}: {e}", path.display()),
                    )
                })?;
                let gamma = p.bool("gamma").unwrap_or(true);
                let rgb = img.into_rgb8();
                // The sRGB curve once per byte value, not once per texel.
                let table: Vec<f32> = (0..=255u8)
                    .map(|c| {
                        let v = c as f32 / 255.0;
                        if !gamma {
                            v
                        } else if v <= 0.04045 {
                            v / 12.92
                        } else {
                            ((v + 0.055) / 1.055).powf(2.4)
                        }
                    })
                    .collect();
                let decode = |c: u8| table[c as usize];
                Texture::Image {
                    width: rgb.width(),
                    height: rgb.height(),
                    texels: rgb
                        .pixels()
                        .map(|p| Vec3::new(decode(p[0]), decode(p[1]), decode(p[2])))
                        .collect(),
                    scale,
                }
            }
            "checkerboard" => {
                let color =
                    |n: &str, d: f32| self.checked_color(p.rgb(n).unwrap_or(Vec3::splat(d)), n);
                Texture::Checkerboard {
                    even: color("tex1", 1.0)?,
                    odd: color("tex2", 0.0)?,
                    scale,
                }
            }
            "constant" => {
                Texture::Constant(self.checked_color(p.rgb("value").unwrap_or(Vec3::ONE), "value")?)
            }
            other => {
                self.out
                    .ignored
                    .insert(format!("texture \"{other}\" (rendered as constant 0.5)"));
                Texture::Constant(Vec3::splat(0.5))
            }
        };
        self.out.textures.insert(name, tex);
        Ok(())
    }

    /// Line of the last token read (the last line at the end of the file).
    fn line(&self) -> usize {
        self.tokens
            .get(self.at.min(self.tokens.len()).saturating_sub(1))
            .map_or(0, |t| t.1)
    }

    fn shape(&mut self) -> Result<(), SceneError> {
        let ty = self.string()?;
        let p = self.params()?;
        let mesh = match ty.as_str() {
            "trianglemesh" => {
                let pos = p.nums("P").unwrap_or_default();
                let idx = p.nums("indices").unwrap_or_default();
                if pos.len() % 3 != 0 || idx.len() % 3 != 0 {
                    return self.err("trianglemesh needs P and indices in multiples of 3");
                }
                let positions: Vec<Vec3> = pos.chunks_exact(3).map(vec3).collect();
                let n = positions.len();
                if idx
                    .iter()
                    .any(|&i| i < 0.0 || i as usize >= n || i.fract() != 0.0)
                {
                    return self.err(format!("trianglemesh index out of range (0..{n})"));
                }
                let normals = p
                    .nums("N")
                    .filter(|v| v.len() == 3 * n)
                    .map(|v| v.chunks_exact(3).map(vec3).collect());
                // "float uv" (older pbrt-v3), "point2 uv" or "st".
                let uvs = p
                    .nums("uv")
                    .or_else(|| p.nums("st"))
                    .filter(|v| v.len() == 2 * n)
                    .map(|v| {
                        v.chunks_exact(2)
                            .map(|c| Vec2::new(c[0] as f32, c[1] as f32))
                            .collect()
                    });
                Mesh {
                    positions,
                    normals,
                    uvs,
                    indices: idx
                        .chunks_exact(3)
                        .map(|c| [c[0] as u32, c[1] as u32, c[2] as u32])
                        .collect(),
                }
            }
            "plymesh" => {
                let file = p.string("filename").unwrap_or_default();
                ply::read(&self.dir.join(file))?
            }
            other => {
                self.out.ignored.insert(format!("Shape \"{other}\""));
                return Ok(());
            }
        };
        let ctm = self.state.ctm;
        let mut mesh = mesh.transformed(&ctm);
        let out_of_range = |v: &Vec3| !(v.is_finite() && v.abs().max_element() <= MAX_COORDINATE);
        if let Some(p) = mesh.positions.iter().find(|p| out_of_range(p)) {
            return self.err(format!(
                "a vertex of the {ty} is not finite or lies beyond ±{MAX_COORDINATE:e} after its transform ({p})"
            ));
        }
        if let Some(n) = mesh.normals.iter().flatten().find(|n| !n.is_finite()) {
            return self.err(format!("a normal of the {ty} is not finite ({n})"));
        }
        if let Some(uv) = mesh.uvs.iter().flatten().find(|uv| !uv.is_finite()) {
            return self.err(format!(
                "a texture coordinate of the {ty} is not finite ({uv})"
            ));
        }
        if ctm.determinant() < 0.0 && mesh.normals.is_none() {
            // pbrt flips the orientation of shapes under a mirroring transform.
            mesh.indices.iter_mut().for_each(|t| t.swap(1, 2));
        }
        let material = match self.state.material {
            Some(m) => m,
            None => {
                self.out.materials.push(Material::Diffuse {
                    reflectance: Texture::Constant(Vec3::splat(0.5)),
                });
                let m = self.out.materials.len() as u32 - 1;
                self.state.material = Some(m);
                m
            }
        };
        self.out.meshes.push((mesh, material, self.state.emission));
        Ok(())
    }

    fn finish(self) -> Result<Loaded, SceneError> {
        let Some(camera_from_world) = self.out.camera_from_world else {
            return Err(SceneError::at(&self.path, 0, "no Camera directive".into()));
        };
        let resolution = self.out.resolution.unwrap_or(Resolution::new(640, 480));
        let camera = Camera {
            camera_to_world: camera_from_world.inverse(),
            fov_degrees: self.out.fov,
            resolution,
        };
        let mut scene = Scene::new(camera);
        scene.materials = self.out.materials;
        let mut ignored = self.out.ignored;
        let skipped: usize = self
            .out
            .meshes
            .iter()
            .map(|(mesh, material, emission)| scene.add_mesh(mesh, *material, *emission))
            .sum();
        if skipped > 0 {
            ignored.insert(format!("{skipped} degenerate triangles (zero area)"));
        }
        scene.environment = self.out.environment;
        scene.max_depth = self.out.max_depth.unwrap_or(16);
        Ok(Loaded { scene, ignored })
    }
}

/// The largest film side the loader accepts (the film's memory is checked
/// again when a render allocates it).
pub const MAX_FILM_SIDE: u32 = 65536;

fn vec3(v: &[f64]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load_str(text: &str) -> Result<Loaded, SceneError> {
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("strata-pbrt-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("scene.pbrt");
        std::fs::write(&path, text).unwrap();
        let r = load(&path);
        std::fs::remove_dir_all(&dir).unwrap();
        r
    }

    const MINIMAL: &str = r#"
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 40 ]
Film "image" "integer xresolution" [ 32 ] "integer yresolution" [ 16 ]
Sampler "sobol"
WorldBegin
  AttributeBegin
    AreaLightSource "diffuse" "rgb L" [ 4 4 4 ]
    Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point P" [ -1 -1 0 1 -1 0 0 1 0 ] "point2 uv" [ 0 0 1 0 0 1 ]
  AttributeEnd
  Material "plastic" "rgb Kd" [ 0.5 0.5 0.5 ] "float roughness" 0.1
  Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point P" [ -1 -1 -1 1 -1 -1 0 1 -1 ] "float uv" [ 0 0 1 0 0 1 ]
  Shape "sphere" "float radius" 1
  Volume "foo"
WorldEnd
"#;

    #[test]
    fn minimal_scene_loads_and_reports_what_it_skipped() {
        let l = load_str(MINIMAL).unwrap();
        assert_eq!(l.scene.triangles.len(), 2);
        assert_eq!(l.scene.lights.len(), 1);
        assert_eq!(l.scene.camera.resolution, Resolution::new(32, 16));
        assert!(l.ignored.contains("Shape \"sphere\"") && l.ignored.contains("Volume"));
        // pbrt's LookAt: the camera at +5 z looking at the origin sees world +x on the image's left.
        let (o, d) = l.scene.camera.ray(0.0, 8.0);
        assert!((o - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-5 && d.x > 0.0 && d.z < 0.0);
    }

    /// Every number the loader reads is checked: each edit of the minimal
    /// scene below is an error naming its line and what is wrong.
    #[test]
    fn bad_numbers_are_errors_that_say_what_is_wrong() {
        let cases = [
            (
                "LookAt 0 0 5",
                "Translate nan 0 0\nLookAt 0 0 5",
                "Translate needs finite",
            ),
            (
                "LookAt 0 0 5",
                "Rotate nan 0 1 0\nLookAt 0 0 5",
                "Rotate needs finite",
            ),
            ("LookAt 0 0 5", "Scale 0 0 0\nLookAt 0 0 5", "Scale by zero"),
            (
                "LookAt 0 0 5",
                "Scale 1e30 1e30 1e30\nLookAt 0 0 5",
                "singular or non-finite",
            ),
            (
                "LookAt 0 0 5",
                "LookAt inf 0 0 0 0 0 0 1 0\nLookAt 0 0 5",
                "LookAt needs finite",
            ),
            ("[ 40 ]", "[ nan ]", "fov must be in (0, 180)"),
            ("[ 40 ]", "[ 180 ]", "fov must be in (0, 180)"),
            (
                "xresolution\" [ 32 ]",
                "xresolution\" [ 2.5 ]",
                "`xresolution` must be a whole number",
            ),
            (
                "yresolution\" [ 16 ]",
                "yresolution\" [ nan ]",
                "`yresolution` must be a whole number",
            ),
            (
                "Sampler \"sobol\"",
                "Integrator \"path\" \"integer maxdepth\" [ nan ]",
                "`maxdepth` must be a whole number",
            ),
            (
                "Sampler \"sobol\"",
                "Integrator \"path\" \"integer maxdepth\" [ 0 ]",
                "`maxdepth` must be a whole number",
            ),
            (
                "\"float roughness\" 0.1",
                "\"float roughness\" nan",
                "roughness must be finite",
            ),
            ("[ 4 4 4 ]", "[ 4 nan 4 ]", "`L` must be finite"),
            (
                "[ -1 -1 0 1",
                "[ -1 -1 nan 1",
                "is not finite or lies beyond",
            ),
            (
                "WorldBegin",
                "WorldBegin\nScale 1e11 1e11 1e11",
                "is not finite or lies beyond",
            ),
        ];
        for (from, to, message) in cases {
            assert!(MINIMAL.contains(from), "{from}");
            let text = MINIMAL.replacen(from, to, 1);
            let e = load_str(&text).unwrap_err().to_string();
            assert!(e.contains(message), "{to}: {e}");
            assert!(e.contains("scene.pbrt:"), "{to}: no line in {e}");
        }
    }

    #[test]
    fn malformed_files_name_the_line() {
        let cases = [
            (
                "Camera \"perspective\"\nWorldBegin\nShape \"trianglemesh\" \"integer indices\" [ 0 1 5 ] \"point P\" [ 0 0 0 1 0 0 0 1 0 ]\n",
                3,
            ),
            (
                "Camera \"perspective\"\nWorldBegin\nNamedMaterial \"missing\"\n",
                3,
            ),
            ("Camera \"perspective\"\n\nTranslate 1 2\n", 3),
            ("Camera \"perspective\" \"float fov [ 30 ]\n", 1),
            ("AttributeEnd\n", 1),
            (
                "Camera \"perspective\"\nWorldBegin\nShape \"plymesh\" \"string filename\" \"nope.ply\"\n",
                0,
            ),
        ];
        for (text, line) in cases {
            let e = load_str(text).unwrap_err();
            assert!(
                e.file.ends_with("scene.pbrt") || e.file.ends_with("nope.ply"),
                "{e}"
            );
            if line > 0 {
                assert_eq!(e.line, line, "{text}: {e}");
            }
        }
        assert!(
            load(Path::new("/nonexistent/scene.pbrt"))
                .unwrap_err()
                .to_string()
                .contains("/nonexistent/scene.pbrt")
        );
    }
}
