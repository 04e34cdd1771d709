//! The parser's state and its directives: tokens and parameter lists
//! read, the graphics state's transforms and attributes, the camera, film
//! and lights, and the scene made at the end. Materials and textures are
//! read in `materials.rs`, shapes in `shapes.rs`.

use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;

use glam::{Mat4, Vec3};
use strata_engine::Resolution;

use super::syntax::{Params, Token, Value};
use crate::SceneError;
use crate::material::{Material, Texture};
use crate::scene::{Camera, Mesh, Scene};

/// A loaded scene and what the loader skipped.
#[derive(Debug)]
pub struct Loaded {
    /// The scene.
    pub scene: Scene,
    /// Directives and types that were not understood (each named once).
    pub ignored: BTreeSet<String>,
}

#[derive(Clone, Debug, Default)]
pub(super) struct State {
    pub(super) ctm: Mat4,
    pub(super) material: Option<u32>,
    pub(super) emission: Option<Vec3>,
}

#[derive(Default)]
pub(super) struct Output {
    pub(super) camera_from_world: Option<Mat4>,
    pub(super) fov: f32,
    pub(super) resolution: Option<Resolution>,
    pub(super) max_depth: Option<u32>,
    pub(super) materials: Vec<Material>,
    pub(super) named: HashMap<String, u32>,
    pub(super) textures: HashMap<String, Texture>,
    pub(super) meshes: Vec<(Mesh, u32, Option<Vec3>)>,
    pub(super) environment: Option<Vec3>,
    pub(super) ignored: BTreeSet<String>,
}

pub(super) struct Parser {
    pub(super) path: PathBuf,
    pub(super) dir: PathBuf,
    pub(super) tokens: Vec<(Token, usize)>,
    pub(super) at: usize,
    pub(super) state: State,
    pub(super) out: Output,
}

impl Parser {
    pub(super) fn err<T>(&self, message: impl Into<String>) -> Result<T, SceneError> {
        Err(SceneError::at(&self.path, self.line(), message.into()))
    }

    pub(super) fn next(&mut self) -> Option<Token> {
        let t = self.tokens.get(self.at).map(|t| t.0.clone());
        self.at += 1;
        t
    }

    pub(super) fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.at).map(|t| &t.0)
    }

    pub(super) fn string(&mut self) -> Result<String, SceneError> {
        match self.next() {
            Some(Token::Str(s)) => Ok(s),
            other => self.err(format!("expected a quoted string, found {other:?}")),
        }
    }

    /// `n` numbers, bare or in brackets.
    pub(super) fn numbers(&mut self, n: usize) -> Result<Vec<f64>, SceneError> {
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

    pub(super) fn params(&mut self) -> Result<Params, SceneError> {
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

    pub(super) fn run(mut self) -> Result<Loaded, SceneError> {
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
    pub(super) fn finite_numbers(
        &mut self,
        n: usize,
        directive: &str,
    ) -> Result<Vec<f64>, SceneError> {
        let v = self.numbers(n)?;
        if v.iter().any(|x| !x.is_finite()) {
            return self.err(format!("{directive} needs finite numbers, got {v:?}"));
        }
        Ok(v)
    }

    /// Makes `m` the current transform: finite and invertible (a singular
    /// transform flattens what follows; a huge one overflows f32).
    pub(super) fn set_transform(&mut self, m: Mat4) -> Result<(), SceneError> {
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
    pub(super) fn whole(
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

    pub(super) fn matrix(&mut self) -> Result<Mat4, SceneError> {
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
    pub(super) fn look_at(&self, eye: Vec3, target: Vec3, up: Vec3) -> Result<Mat4, SceneError> {
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

    /// Line of the last token read (the last line at the end of the file).
    pub(super) fn line(&self) -> usize {
        self.tokens
            .get(self.at.min(self.tokens.len()).saturating_sub(1))
            .map_or(0, |t| t.1)
    }

    pub(super) fn finish(self) -> Result<Loaded, SceneError> {
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

pub(super) fn vec3(v: &[f64]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}
