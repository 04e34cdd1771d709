//! MC over unidirectional paths against Tungsten's path tracer (B. Bitterli),
//! each on the same scene in its own format: the Cornell box
//! (`scenes/cornell-box/scene.pbrt` and `studies/tungsten/cornell.json`) and
//! a glass sphere's caustic in it (`studies/tungsten/caustic.*`), 256x256,
//! box-filtered pixels, 2 threads, the two renderers alternated run by run.
//!
//! Each renderer is scored against its own runs: the variance of a pixel is
//! the spread of its `--runs` renders about their mean (no reference render
//! is needed, and neither renderer's bias enters), summed over channels and
//! averaged over pixels; times the paths per pixel it is the variance of one
//! path, and times the render time (Tungsten's own "Render time", strata's
//! `render` call) the inverse of the efficiency. The means of the two
//! renderers' runs, each `runs x spp` paths a pixel, must agree (z below).
//! Writes `out/against_tungsten/summary.csv`, each renderer's mean image
//! and where the two disagree beyond noise (`SCENE-disagreement.png`).
//!
//! Tungsten builds with `cmake -DCMAKE_BUILD_TYPE=Release
//! -DTARGET_ARCHITECTURE=nehalem .. && make -j2 tungsten`
//! (github.com/tunabrain/tungsten; its CPU detection fails without the flag).
//!
//! ```text
//! cargo run --release -p strata-studies --bin against_tungsten -- --tungsten ~/tungsten/build/tungsten
//! ```

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use clap::Parser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, PathOracle, Resolution, Settings, Silent, render};
use strata::native::{native_tracer, pbrt};
use strata_studies::common::AnyResult;

/// MC's noise per path and per second against Tungsten's.
#[derive(Parser, Debug)]
struct Args {
    /// The `tungsten` binary.
    #[arg(long)]
    tungsten: PathBuf,
    /// Scenes: `cornell`, `caustic`.
    #[arg(long, value_delimiter = ',', default_value = "cornell,caustic")]
    scenes: Vec<String>,
    /// Renders of each renderer per scene (seeds 1, 2, ...; at least 4).
    #[arg(long, default_value_t = 16)]
    runs: u64,
    /// Where the images and the summary go.
    #[arg(long, default_value = "out/against_tungsten")]
    out: PathBuf,
}

/// Paths per pixel of every render: the `spp` of the Tungsten files.
const SPP: u64 = 64;
const SIDE: u32 = 256;

/// One renderer's runs of a scene.
#[derive(Default)]
struct Runs {
    films: Vec<Film>,
    seconds: Vec<f64>,
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    if args.runs < 4 {
        // With two runs both deviate equally from their mean: the standard
        // errors below would read 0.
        return Err("--runs must be at least 4".into());
    }
    std::fs::create_dir_all(&args.out)?;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut csv = String::from(
        "scene,renderer,seconds,variance_per_path,variance_per_path_se,rel_variance_per_path,\
         mean_r,mean_g,mean_b\n",
    );
    for name in &args.scenes {
        let (pbrt_file, json) = match name.as_str() {
            "cornell" => (
                "scenes/cornell-box/scene.pbrt",
                "studies/tungsten/cornell.json",
            ),
            "caustic" => (
                "studies/tungsten/caustic.pbrt",
                "studies/tungsten/caustic.json",
            ),
            _ => return Err(format!("no scene {name}: cornell or caustic").into()),
        };
        let mut scene = pbrt::load(&root.join(pbrt_file))?.scene;
        scene.camera.resolution = Resolution::new(SIDE, SIDE);
        let tracer = native_tracer(scene)?;
        let (mut ours, mut theirs) = (Runs::default(), Runs::default());
        for seed in 1..=args.runs {
            let settings = Settings {
                seed,
                budget: Budget::samples_per_pixel(SPP, tracer.resolution()),
                method: Method::Mc,
            };
            let start = Instant::now();
            let film = render(&tracer, &MaxChannel, &settings, &Silent)?.film;
            ours.seconds.push(start.elapsed().as_secs_f64());
            ours.films.push(film);
            let (film, seconds) = tungsten(&args.tungsten, &root.join(json), seed, &args.out)?;
            theirs.films.push(film);
            theirs.seconds.push(seconds);
            eprintln!(
                "{name} run {seed}: strata {:.2} s, Tungsten {seconds:.2} s",
                ours.seconds.last().unwrap_or(&0.0)
            );
        }
        let (m_ours, m_theirs) = (mean(&ours.films)?, mean(&theirs.films)?);
        let mut pooled = m_ours.clone();
        pooled.merge(&m_theirs)?;
        pooled.scale(0.5);
        println!("{name} (256x256, {SPP} spp a run, {} runs each)", args.runs);
        println!("  renderer  seconds  variance/path (se)     rel. variance/path  mean R G B");
        let mut rows = Vec::new();
        for (renderer, runs, m) in [("strata", &ours, &m_ours), ("Tungsten", &theirs, &m_theirs)] {
            let (v, se, rel) = variance(&runs.films, m, &pooled);
            let seconds = runs.seconds.iter().sum::<f64>() / runs.seconds.len() as f64;
            // Per path: a pixel's variance times the paths it averaged.
            let [v_path, se_path, rel_path] = [v, se, rel].map(|x| x * SPP as f64);
            let [r, g, b] = [0, 1, 2].map(|c| m.channel_mean(c));
            println!(
                "  {renderer:<9} {seconds:6.2}  {v_path:.4e} ({se_path:.1e})  {rel_path:.4e}          {r:.4} {g:.4} {b:.4}"
            );
            csv += &format!(
                "{name},{renderer},{seconds:.4},{v_path:.6e},{se_path:.3e},{rel_path:.6e},{r:.6},{g:.6},{b:.6}\n"
            );
            let mean_file = args.out.join(format!("{name}-{renderer}-mean.exr"));
            strata::io::write_exr(m, &mean_file)?;
            strata::io::write_png(m, 0.0, mean_file.with_extension("png"))?;
            rows.push((v, se, seconds, [r, g, b], runs));
        }
        let [
            (v_s, se_s, t_s, mean_s, ours),
            (v_t, se_t, t_t, mean_t, theirs),
        ] = [rows[0], rows[1]];
        // The channel means' standard errors from the spread of the runs' means.
        for c in 0..3 {
            let se = |runs: &Runs| {
                let means: Vec<f64> = runs.films.iter().map(|f| f.channel_mean(c)).collect();
                let m = means.iter().sum::<f64>() / means.len() as f64;
                let var =
                    means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (means.len() - 1) as f64;
                (var / means.len() as f64).sqrt()
            };
            let z = (mean_s[c] - mean_t[c]) / (se(ours).powi(2) + se(theirs).powi(2)).sqrt();
            println!(
                "  channel {c}: strata / Tungsten mean {:.5} (z {z:.2})",
                mean_s[c] / mean_t[c]
            );
        }
        let z = disagreement(&ours.films, &theirs.films)?;
        strata::io::write_png(&z, 0.0, args.out.join(format!("{name}-disagreement.png")))?;
        let ratio = v_s / v_t;
        let ratio_se = ratio * ((se_s / v_s).powi(2) + (se_t / v_t).powi(2)).sqrt();
        println!(
            "  variance per path strata / Tungsten: {ratio:.3} ± {ratio_se:.3}; time {:.3}; at equal time {:.3}",
            t_s / t_t,
            ratio * t_s / t_t
        );
    }
    std::fs::write(args.out.join("summary.csv"), csv)?;
    println!("wrote {}", args.out.join("summary.csv").display());
    Ok(())
}

/// One Tungsten render of `json` with `seed` on 2 threads: its image and
/// its own render time.
fn tungsten(binary: &Path, json: &Path, seed: u64, out: &Path) -> AnyResult<(Film, f64)> {
    let dir = out.join("tungsten");
    std::fs::create_dir_all(&dir)?;
    let output = Command::new(binary)
        .args(["-t", "2", "--seed", &seed.to_string(), "-d"])
        .arg(&dir)
        .arg(json)
        .output()?;
    let log = String::from_utf8_lossy(&output.stdout);
    let time = log
        .lines()
        .find_map(|l| l.split("Render time ").nth(1))
        .ok_or_else(|| format!("Tungsten gave no render time:\n{log}"))?;
    Ok((read_pfm(&dir.join("render.pfm"))?, seconds(time)?))
}

/// Tungsten's durations: "3s 489ms", "1m 2s 5ms".
fn seconds(text: &str) -> AnyResult<f64> {
    let mut total = 0.0;
    for part in text.split_whitespace() {
        let digits = part.trim_end_matches(char::is_alphabetic);
        let value: f64 = digits.parse()?;
        total += value
            * match &part[digits.len()..] {
                "h" => 3600.0,
                "m" => 60.0,
                "s" => 1.0,
                "ms" => 1e-3,
                unit => return Err(format!("unknown unit {unit} in {text}").into()),
            };
    }
    Ok(total)
}

/// A little-endian RGB PFM (rows bottom to top) as a film.
fn read_pfm(path: &Path) -> AnyResult<Film> {
    let bytes = std::fs::read(path)?;
    let bad = || format!("{}: not a little-endian RGB PFM", path.display());
    // Three header lines ("PF", "W H", a negative scale), then the floats.
    let mut header = Vec::new();
    let mut at = 0;
    for _ in 0..3 {
        let end = at
            + bytes[at..]
                .iter()
                .position(|b| *b == b'\n')
                .ok_or_else(bad)?;
        header.push(String::from_utf8_lossy(&bytes[at..end]).into_owned());
        at = end + 1;
    }
    let size: Vec<u32> = header[1]
        .split_whitespace()
        .filter_map(|v| v.parse().ok())
        .collect();
    let data = &bytes[at..];
    let [w, h] = size[..] else {
        return Err(bad().into());
    };
    if header[0] != "PF"
        || !header[2].trim().starts_with('-')
        || data.len() != 12 * (w * h) as usize
    {
        return Err(bad().into());
    }
    let mut film = Film::new(Resolution::new(w, h), 3);
    let values = film.data_mut();
    for (i, v) in data.chunks_exact(4).enumerate() {
        let (pixel, c) = (i as u32 / 3, i % 3);
        let (x, y) = (pixel % w, h - 1 - pixel / w);
        values[(y * w + x) as usize * 3 + c] = f32::from_le_bytes([v[0], v[1], v[2], v[3]]) as f64;
    }
    Ok(film)
}

/// Where the two renderers' means disagree: each pixel's difference of
/// luminance (strata's less Tungsten's) over its standard error from both
/// runs' spread, red above and blue below, full at 4 standard errors.
fn disagreement(ours: &[Film], theirs: &[Film]) -> AnyResult<Film> {
    let r = ours[0].resolution();
    let mut z = Film::new(r, 3);
    let luminance = |films: &[Film], i: usize| -> (f64, f64) {
        let n = films.len() as f64;
        let values: Vec<f64> = films.iter().map(|f| f.luminance(i)).collect();
        let m = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, var / n)
    };
    for i in 0..(r.width * r.height) as usize {
        let ((a, va), (b, vb)) = (luminance(ours, i), luminance(theirs, i));
        let score = if va + vb > 0.0 {
            (a - b) / (va + vb).sqrt()
        } else {
            0.0
        };
        let level = (score.abs() / 4.0).min(1.0);
        let pixel = &mut z.data_mut()[3 * i..3 * i + 3];
        pixel.copy_from_slice(&if score > 0.0 {
            [level, 0.0, 0.0]
        } else {
            [0.0, 0.0, level]
        });
    }
    Ok(z)
}

/// The mean of films.
fn mean(films: &[Film]) -> AnyResult<Film> {
    let mut sum = films[0].clone();
    for f in &films[1..] {
        sum.merge(f)?;
    }
    sum.scale(1.0 / films.len() as f64);
    Ok(sum)
}

/// Runs' variance about their mean `m`, summed over channels and averaged
/// over pixels (unbiased: `n / (n - 1)`); its standard error from the
/// spread of the runs' own squared deviations; and the same relative to the
/// square of `pooled` (+ 0.01).
fn variance(films: &[Film], m: &Film, pooled: &Film) -> (f64, f64, f64) {
    let n = films.len() as f64;
    let pixels = (m.data().len() / 3) as f64;
    let (mut per_run, mut rel) = (Vec::new(), 0.0);
    for f in films {
        let mut sum = 0.0;
        for ((x, mu), p) in f.data().iter().zip(m.data()).zip(pooled.data()) {
            let d2 = (x - mu).powi(2) * n / (n - 1.0);
            sum += d2;
            rel += d2 / (p * p + 0.01);
        }
        per_run.push(sum / pixels);
    }
    let v = per_run.iter().sum::<f64>() / n;
    let spread = per_run.iter().map(|d| (d - v).powi(2)).sum::<f64>() / (n - 1.0);
    (v, (spread / n).sqrt(), rel / (pixels * n))
}
