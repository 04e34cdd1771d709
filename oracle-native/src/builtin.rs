//! Procedural scenes for fast tests, no data files: `cornell`, `door`,
//! `envplane`, `caustic`, `saturated` and `pool`.

use glam::{Mat4, Vec2, Vec3};
use strata_engine::Resolution;

use crate::material::{ConductorFresnel, Material, Texture};
use crate::scene::{Camera, Mesh, Scene};

/// Names of the built-in scenes.
pub const NAMES: [&str; 6] = [
    "cornell",
    "door",
    "envplane",
    "caustic",
    "saturated",
    "pool",
];

/// The built-in scene called `name`, at `resolution`.
pub fn by_name(name: &str, resolution: Resolution) -> Option<Scene> {
    match name {
        "cornell" => Some(cornell(resolution)),
        "door" => Some(door(resolution)),
        "envplane" => Some(envplane(resolution)),
        "caustic" => Some(caustic(resolution)),
        "saturated" => Some(saturated(resolution)),
        "pool" => Some(pool(resolution)),
        _ => None,
    }
}

/// A quad `a, b, c, d`; its front (where an emitter shines) is the side from
/// which the corners run counter-clockwise.
pub fn quad(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> Mesh {
    Mesh {
        positions: vec![a, b, c, d],
        normals: None,
        uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y]),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// An axis-aligned box from `lo` to `hi`, faces pointing out.
pub fn cuboid(lo: Vec3, hi: Vec3) -> Mesh {
    let p = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { hi.x } else { lo.x },
            if y { hi.y } else { lo.y },
            if z { hi.z } else { lo.z },
        )
    };
    let faces = [
        [
            p(false, false, false),
            p(false, true, false),
            p(true, true, false),
            p(true, false, false),
        ], // -z
        [
            p(false, false, true),
            p(true, false, true),
            p(true, true, true),
            p(false, true, true),
        ], // +z
        [
            p(false, false, false),
            p(false, false, true),
            p(false, true, true),
            p(false, true, false),
        ], // -x
        [
            p(true, false, false),
            p(true, true, false),
            p(true, true, true),
            p(true, false, true),
        ], // +x
        [
            p(false, false, false),
            p(true, false, false),
            p(true, false, true),
            p(false, false, true),
        ], // -y
        [
            p(false, true, false),
            p(false, true, true),
            p(true, true, true),
            p(true, true, false),
        ], // +y
    ];
    merge(faces.iter().map(|f| quad(f[0], f[1], f[2], f[3])))
}

/// A UV sphere with smooth normals.
pub fn sphere(center: Vec3, radius: f32, rings: u32, segments: u32) -> Mesh {
    let mut m = Mesh {
        normals: Some(Vec::new()),
        ..Default::default()
    };
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            m.positions.push(center + radius * n);
            m.normals.as_mut().expect("set above").push(n);
        }
    }
    let row = segments + 1;
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (
                i * row + j,
                i * row + j + 1,
                (i + 1) * row + j + 1,
                (i + 1) * row + j,
            );
            m.indices.push([a, b, c]);
            m.indices.push([a, c, d]);
        }
    }
    m
}

/// A benchmark scene: a sphere of `2·rings·segments` triangles (1M at
/// 500 x 1000) in front of the camera, lit by a quad above it.
pub fn dense_sphere(resolution: Resolution, rings: u32, segments: u32) -> Scene {
    let camera = Camera::look_at(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::ZERO,
        Vec3::Y,
        40.0,
        resolution,
    );
    let mut s = Scene::new(camera);
    let grey = diffuse(&mut s, Vec3::splat(0.7));
    s.add_mesh(&sphere(Vec3::ZERO, 1.0, rings, segments), grey, None);
    let black = diffuse(&mut s, Vec3::ZERO);
    let light = quad(
        Vec3::new(-1., 2., -1.),
        Vec3::new(1., 2., -1.),
        Vec3::new(1., 2., 1.),
        Vec3::new(-1., 2., 1.),
    );
    s.add_mesh(&light, black, Some(Vec3::splat(5.0)));
    s
}

/// The scenes the throughput benchmarks use: the built-ins, `veach-ajar`
/// when the shared scenes are present (a note on stderr otherwise) and a
/// 1M-triangle [`dense_sphere`].
pub fn benchmark_set(resolution: Resolution) -> Vec<(String, Scene)> {
    let mut v: Vec<(String, Scene)> = NAMES
        .iter()
        .filter_map(|n| by_name(n, resolution).map(|s| (n.to_string(), s)))
        .collect();
    match crate::pbrt::load_shared("veach-ajar") {
        Ok(l) => v.push(("veach-ajar".into(), l.scene)),
        Err(e) => eprintln!("skipping veach-ajar: {e}"),
    }
    v.push(("mesh-1M".into(), dense_sphere(resolution, 500, 1000)));
    v
}

fn merge(meshes: impl Iterator<Item = Mesh>) -> Mesh {
    let mut out = Mesh {
        uvs: Some(Vec::new()),
        ..Default::default()
    };
    for m in meshes {
        let base = out.positions.len() as u32;
        out.positions.extend(&m.positions);
        out.uvs
            .as_mut()
            .expect("set above")
            .extend(m.uvs.unwrap_or_else(|| vec![Vec2::ZERO; m.positions.len()]));
        out.indices
            .extend(m.indices.iter().map(|t| t.map(|i| i + base)));
    }
    out
}

fn diffuse(scene: &mut Scene, c: Vec3) -> u32 {
    scene.add_material(Material::Diffuse {
        reflectance: Texture::Constant(c),
    })
}

/// The Cornell box's camera and room: floor, ceiling and back wall of
/// reflectance `white`, the left wall `left`, the right wall `right`, and
/// the materials `[white, left, right, black]` (black for emitters), added
/// in that order before the walls.
fn cornell_room(resolution: Resolution, white: Vec3, left: Vec3, right: Vec3) -> (Scene, [u32; 4]) {
    let camera = Camera::look_at(
        Vec3::new(0.0, 1.0, 6.8),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::Y,
        19.5,
        resolution,
    );
    let mut s = Scene::new(camera);
    let white = diffuse(&mut s, white);
    let left = diffuse(&mut s, left);
    let right = diffuse(&mut s, right);
    let black = diffuse(&mut s, Vec3::ZERO);
    let v = Vec3::new;
    let walls = [
        (
            [
                v(-1., 0., -1.),
                v(-1., 0., 1.),
                v(1., 0., 1.),
                v(1., 0., -1.),
            ],
            white,
        ), // floor
        (
            [
                v(1., 2., 1.),
                v(-1., 2., 1.),
                v(-1., 2., -1.),
                v(1., 2., -1.),
            ],
            white,
        ), // ceiling
        (
            [
                v(-1., 0., -1.),
                v(1., 0., -1.),
                v(1., 2., -1.),
                v(-1., 2., -1.),
            ],
            white,
        ), // back
        (
            [v(1., 0., -1.), v(1., 0., 1.), v(1., 2., 1.), v(1., 2., -1.)],
            right,
        ),
        (
            [
                v(-1., 0., 1.),
                v(-1., 0., -1.),
                v(-1., 2., -1.),
                v(-1., 2., 1.),
            ],
            left,
        ),
    ];
    for ([a, b, c, d], material) in walls {
        s.add_mesh(&quad(a, b, c, d), material, None);
    }
    (s, [white, left, right, black])
}

/// The Cornell box of `scenes/cornell-box` (same geometry, camera
/// and light), built procedurally.
pub fn cornell(resolution: Resolution) -> Scene {
    let (mut s, [white, _, _, black]) = cornell_room(
        resolution,
        Vec3::new(0.725, 0.71, 0.68),
        Vec3::new(0.63, 0.065, 0.05),
        Vec3::new(0.14, 0.45, 0.091),
    );
    let v = Vec3::new;
    let short = cuboid(v(-0.3, 0.0, -0.3), v(0.3, 0.6, 0.3));
    let short = short
        .transformed(&(Mat4::from_translation(v(0.33, 0.0, 0.37)) * Mat4::from_rotation_y(-0.29)));
    s.add_mesh(&short, white, None);
    let tall = cuboid(v(-0.3, 0.0, -0.3), v(0.3, 1.2, 0.3));
    let tall = tall.transformed(
        &(Mat4::from_translation(v(-0.335, 0.0, -0.29)) * Mat4::from_rotation_y(0.34)),
    );
    s.add_mesh(&tall, white, None);
    let light = quad(
        v(-0.24, 1.98, -0.22),
        v(0.23, 1.98, -0.22),
        v(0.23, 1.98, 0.16),
        v(-0.24, 1.98, 0.16),
    );
    s.add_mesh(&light, black, Some(v(17.0, 12.0, 4.0)));
    s.max_depth = 16;
    s
}

/// A room lit only through a narrow opening in its back wall: the light
/// hangs in a second room behind it (the kind of visibility of Gruson et al.'s (2020)
/// "Veach-door").
pub fn door(resolution: Resolution) -> Scene {
    let camera = Camera::look_at(
        Vec3::new(0.0, 1.0, 3.8),
        Vec3::new(0.0, 0.9, 0.0),
        Vec3::Y,
        50.0,
        resolution,
    );
    let mut s = Scene::new(camera);
    let wall = diffuse(&mut s, Vec3::new(0.7, 0.68, 0.65));
    let floor = s.add_material(Material::Diffuse {
        reflectance: Texture::Checkerboard {
            even: Vec3::new(0.6, 0.55, 0.5),
            odd: Vec3::new(0.25, 0.22, 0.2),
            scale: Vec2::splat(8.0),
        },
    });
    let black = diffuse(&mut s, Vec3::ZERO);
    let v = Vec3::new;
    // Front room: x in [-2, 2], y in [0, 2.4], z in [-1, 4]; back room: z in [-3, -1].
    s.add_mesh(
        &quad(
            v(-2., 0., -3.),
            v(-2., 0., 4.),
            v(2., 0., 4.),
            v(2., 0., -3.),
        ),
        floor,
        None,
    );
    s.add_mesh(
        &quad(
            v(2., 2.4, 4.),
            v(-2., 2.4, 4.),
            v(-2., 2.4, -3.),
            v(2., 2.4, -3.),
        ),
        wall,
        None,
    );
    s.add_mesh(
        &quad(
            v(-2., 0., 4.),
            v(-2., 0., -3.),
            v(-2., 2.4, -3.),
            v(-2., 2.4, 4.),
        ),
        wall,
        None,
    );
    s.add_mesh(
        &quad(
            v(2., 0., -3.),
            v(2., 0., 4.),
            v(2., 2.4, 4.),
            v(2., 2.4, -3.),
        ),
        wall,
        None,
    );
    s.add_mesh(
        &quad(
            v(-2., 0., -3.),
            v(2., 0., -3.),
            v(2., 2.4, -3.),
            v(-2., 2.4, -3.),
        ),
        wall,
        None,
    );
    s.add_mesh(
        &quad(
            v(2., 0., 4.),
            v(-2., 0., 4.),
            v(-2., 2.4, 4.),
            v(2., 2.4, 4.),
        ),
        wall,
        None,
    );
    // The dividing wall at z = -1 with a door gap x in [0.2, 0.5], y < 2.
    let divider = [
        cuboid(v(-2., 0., -1.05), v(0.2, 2.4, -0.95)),
        cuboid(v(0.5, 0., -1.05), v(2., 2.4, -0.95)),
        cuboid(v(0.2, 2.0, -1.05), v(0.5, 2.4, -0.95)),
    ];
    for part in divider {
        s.add_mesh(&part, wall, None);
    }
    // The light: facing away from the door, toward the back room's far wall.
    let light = quad(
        v(-0.8, 1.2, -1.6),
        v(-0.8, 1.8, -1.6),
        v(0.8, 1.8, -1.6),
        v(0.8, 1.2, -1.6),
    );
    s.add_mesh(&light, black, Some(v(60.0, 52.0, 40.0)));
    s.max_depth = 16;
    s
}

/// A diffuse plane under a constant environment (Gruson et al. 2020, fig. 2).
pub fn envplane(resolution: Resolution) -> Scene {
    let camera = Camera::look_at(
        Vec3::new(0.0, 2.0, 4.0),
        Vec3::ZERO,
        Vec3::Y,
        45.0,
        resolution,
    );
    let mut s = Scene::new(camera);
    let grey = diffuse(&mut s, Vec3::splat(0.5));
    s.add_mesh(
        &quad(
            Vec3::new(-3., 0., -3.),
            Vec3::new(-3., 0., 3.),
            Vec3::new(3., 0., 3.),
            Vec3::new(3., 0., -3.),
        ),
        grey,
        None,
    );
    s.environment = Some(Vec3::ONE);
    s.max_depth = 8;
    s
}

/// A glass sphere on a floor under a small light, casting a caustic, with a
/// mirror behind it in which the caustic is seen again (the specular paths
/// that tempering, Šik 2018, sec. 5.2, is for).
pub fn caustic(resolution: Resolution) -> Scene {
    let camera = Camera::look_at(
        Vec3::new(0.0, 1.6, 4.0),
        Vec3::new(0.0, 0.5, 0.0),
        Vec3::Y,
        40.0,
        resolution,
    );
    let mut s = Scene::new(camera);
    let floor = diffuse(&mut s, Vec3::splat(0.6));
    let black = diffuse(&mut s, Vec3::ZERO);
    let glass = s.add_material(Material::Dielectric {
        eta: 1.5,
        alpha: 0.0,
    });
    let mirror = s.add_material(Material::Conductor {
        fresnel: ConductorFresnel::Constant(Vec3::splat(0.95)),
        alpha: 0.0,
    });
    let v = Vec3::new;
    s.add_mesh(
        &quad(
            v(-4., 0., -4.),
            v(-4., 0., 4.),
            v(4., 0., 4.),
            v(4., 0., -4.),
        ),
        floor,
        None,
    );
    s.add_mesh(
        &quad(
            v(-2., 0., -1.5),
            v(2., 0., -1.5),
            v(2., 2.5, -1.5),
            v(-2., 2.5, -1.5),
        ),
        mirror,
        None,
    );
    s.add_mesh(&sphere(v(0.0, 0.5, 0.0), 0.5, 24, 48), glass, None);
    let light = quad(
        v(0.9, 2.5, 0.7),
        v(1.2, 2.5, 0.7),
        v(1.2, 2.5, 1.0),
        v(0.9, 2.5, 1.0),
    );
    s.add_mesh(&light, black, Some(v(400.0, 380.0, 340.0)));
    s.max_depth = 16;
    s
}

/// The Cornell box's room with fully saturated walls (left red, right blue:
/// each reflects one channel only), a mirror sphere and a glass sphere under
/// a large light: every channel lights a region of its own, and the glass
/// adds caustics. A scene where an estimator that gets one channel's share
/// wrong shows it.
pub fn saturated(resolution: Resolution) -> Scene {
    let (mut s, [_, _, _, black]) = cornell_room(
        resolution,
        Vec3::splat(0.75),
        Vec3::new(0.8, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 0.8),
    );
    let glass = s.add_material(Material::Dielectric {
        eta: 1.5,
        alpha: 0.0,
    });
    let mirror = s.add_material(Material::Conductor {
        fresnel: ConductorFresnel::Constant(Vec3::splat(0.95)),
        alpha: 0.0,
    });
    let v = Vec3::new;
    s.add_mesh(&sphere(v(-0.45, 0.4, -0.35), 0.4, 24, 48), mirror, None);
    s.add_mesh(&sphere(v(0.45, 0.35, 0.3), 0.35, 24, 48), glass, None);
    let light = quad(
        v(-0.5, 1.98, -0.5),
        v(0.5, 1.98, -0.5),
        v(0.5, 1.98, 0.5),
        v(-0.5, 1.98, 0.5),
    );
    s.add_mesh(&light, black, Some(Vec3::splat(4.0)));
    s.max_depth = 16;
    s
}

/// A room half filled with water under a small light, seen from above the
/// water: the floor and the walls below the surface are lit only through
/// it and seen only through it, a specular-diffuse-specular caustic made
/// glossy (GGX α = 0.2, a rippled surface). Next-event estimation
/// is blocked by the surface and camera paths reach the small light after
/// two refractions only by chance: the scene where unidirectional sampling
/// fails and bidirectional connections at the glossy surface do not.
pub fn pool(resolution: Resolution) -> Scene {
    let (mut s, [_, _, _, black]) = cornell_room(
        resolution,
        Vec3::splat(0.75),
        Vec3::new(0.2, 0.5, 0.7),
        Vec3::new(0.7, 0.6, 0.3),
    );
    s.camera = Camera::look_at(
        Vec3::new(0.0, 1.7, 0.95),
        Vec3::new(0.0, 0.3, -0.5),
        Vec3::Y,
        60.0,
        resolution,
    );
    let water = s.add_material(Material::Dielectric {
        eta: 1.33,
        alpha: 0.2,
    });
    let v = Vec3::new;
    let surface = quad(
        v(-1., 0.6, -1.),
        v(-1., 0.6, 1.),
        v(1., 0.6, 1.),
        v(1., 0.6, -1.),
    );
    s.add_mesh(&surface, water, None);
    let light = quad(
        v(-0.15, 1.98, -0.15),
        v(0.15, 1.98, -0.15),
        v(0.15, 1.98, 0.15),
        v(-0.15, 1.98, 0.15),
    );
    s.add_mesh(&light, black, Some(Vec3::splat(60.0)));
    s.max_depth = 16;
    s
}
