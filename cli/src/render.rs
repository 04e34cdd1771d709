//! `strata render`: a scene rendered whole or as one task of a split
//! render, and what it reports.

use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use crate::args::{Args, Backend, THREADS_PER_CORE, differences, method};
use crate::files::{
    checkpoint_bytes, checkpoint_key, checkpoint_limit, checkpoint_path, open_checkpoint, output,
    part_path, prepare_outputs, read_checkpoint, replace, write,
};
use crate::out::AnyResult;
use crate::watch::{Ended, Every, Watch};
use indicatif::{ProgressBar, ProgressStyle};
use strata::embree::EmbreeIntersector;
use strata::engine::MaxChannel;
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::diagnostics;
use strata::engine::{
    Budget, Checkpoint, Error, Extras, Method, Output, PathOracle, Resolution, Settings, render,
    resume,
};
use strata::engine::{Ladder, Tempering};
use strata::engine::{Task, render_task, resume_task};
use strata::native::{PathSampler, PathTracer, builtin, native_tracer};

pub(crate) fn run(args: &Args) -> AnyResult<Ended> {
    prepare_outputs(args)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = args.threads;
    if threads > THREADS_PER_CORE * cores {
        threads = THREADS_PER_CORE * cores;
        warn!(
            "note: --threads {} capped at {threads} ({THREADS_PER_CORE} per core); the image does not depend on it",
            args.threads
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(args.stack_size as usize * (1 << 20))
        .build()?;
    let resolution = Resolution::new(args.width.unwrap_or(256), args.height.unwrap_or(256));
    let analytic = matches!(args.scene.as_str(), "procedural" | "mixture");
    if analytic && args.path_sampler != PathSampler::Unidirectional.name() {
        return Err(format!(
            "--path-sampler {}: {} is an analytic target, not a scene the path tracer renders",
            args.path_sampler, args.scene
        )
        .into());
    }
    if args.path_sampler == PathSampler::Multiplexed.name()
        && !matches!(args.method.as_str(), "pssmlt" | "replica")
    {
        warn!(
            "note: multiplexed paths (one strategy each) are for Metropolis chains: --method {} on them \
             measured up to 100x noisier than on bidirectional paths (docs/RESULTS.md); \
             multiplexed MLT is --method pssmlt",
            args.method
        );
    }
    let (rendered, reference) = pool.install(|| -> AnyResult<_> {
        Ok(match args.scene.as_str() {
            "procedural" => {
                let image = ProceduralImage::showcase(resolution);
                (render_with(&image, args)?, Some(image.reference()))
            }
            "mixture" => {
                let mixture = GaussianMixture::random(12, 4, (0.02, 0.1), resolution, args.seed);
                (render_with(&mixture, args)?, Some(mixture.reference(1.0)))
            }
            name => {
                let scene = match builtin::by_name(name, resolution) {
                    Some(scene) => scene,
                    None => {
                        let path = std::path::Path::new(name);
                        if !path.exists() {
                            return Err(format!(
                                "{name}: no such file, and no built-in scene of that name ({}, procedural, mixture)",
                                builtin::NAMES.join(", ")
                            )
                            .into());
                        }
                        let loaded = strata::native::pbrt::load(path)?;
                        for skipped in &loaded.ignored {
                            warn!("note: {name}: ignored {skipped}");
                        }
                        let mut scene = loaded.scene;
                        scene.camera.resize(args.width, args.height);
                        scene
                    }
                };
                say!(
                    "{name}: {} triangles, {} emissive",
                    scene.triangles.len(),
                    scene.lights.len()
                );
                if scene.lights.is_empty() && scene.environment.is_none() {
                    return Err(format!(
                        "{name} has no light (no emissive triangle, no environment): every path would be black"
                    )
                    .into());
                }
                let sampler = PathSampler::from_name(&args.path_sampler)
                    .ok_or("unknown path sampler")?;
                match args.backend {
                    Backend::Native => {
                        let mut tracer = native_tracer(scene)?;
                        tracer.sampler = sampler;
                        (render_with(&tracer, args)?, None)
                    }
                    Backend::Embree => {
                        let embree = EmbreeIntersector::new(&scene.triangles)?;
                        let mut tracer = PathTracer::new(scene, embree);
                        tracer.sampler = sampler;
                        (render_with(&tracer, args)?, None)
                    }
                }
            }
        })
    })?;
    let (output, ended) = rendered;
    let Some(output) = output else {
        return Ok(ended);
    };
    write(&output.film, &args.out, args.exposure, false)?;
    let s = &output.stats;
    say!(
        "paths: {} (+{} bootstrap), invalid: {}",
        s.samples,
        s.bootstrap_samples,
        s.invalid_samples
    );
    if s.emission_rays > 0 {
        say!(
            "camera rays for the emission seen directly: {} ({:.2} a path)",
            s.emission_rays,
            s.emission_rays as f64 / s.samples.max(1) as f64
        );
    }
    if s.samples > 0 && s.invalid_samples >= s.samples {
        warn!(
            "warning: every path was invalid (the oracle returned NaN, infinite or negative radiance): the image is black"
        );
    }
    if let Some(b) = s.normalization {
        say!(
            "b = {b:.6} (relative standard error {:.2} %), acceptance = {:.3}",
            100.0 * s.normalization_error.unwrap_or(f64::NAN),
            s.chains.acceptance_rate()
        );
    }
    if let Some(reference) = reference {
        let e = diagnostics::compare(&output.film, &reference)?;
        say!(
            "vs exact: MAPE {:.4}  relMSE {:.5}  L1 {:.5}  L2 {:.5}",
            e.mape,
            e.rel_mse,
            e.l1,
            e.l2
        );
    }
    Ok(ended)
}

/// Renders `oracle` as `args` say: the image, or for a task (`--task-index`)
/// no image and its partial result written to OUT.part.
pub(crate) fn render_with<O: PathOracle>(
    oracle: &O,
    args: &Args,
) -> AnyResult<(Option<Output>, Ended)> {
    let resolution = oracle.resolution();
    let budget = match args.time {
        Some(t) => Budget::Time(t),
        None => Budget::samples_per_pixel(args.spp, resolution),
    };
    let mut settings = Settings {
        seed: args.seed,
        budget,
        method: method(args)?,
    };
    let resumed = match &args.resume {
        Some(path) => {
            let most = checkpoint_limit(&settings, oracle, args.task().unwrap_or(Task::WHOLE));
            let bytes = read_checkpoint(path, most)?;
            let checkpoint = open_checkpoint(bytes, checkpoint_key()?.as_deref())
                .map_err(|e| format!("in checkpoint {}: {e}", path.display()))?;
            // The method's settings must be the ones the render started
            // with: a flag that differs is an error naming it.
            let inside = |e: Error| format!("in checkpoint {}: {e}", path.display());
            let saved = checkpoint.settings().map_err(inside)?;
            let task = checkpoint.task().map_err(inside)?;
            if task != Task::WHOLE && args.task().is_none() {
                return Err(format!(
                    "{} is task {} of {}'s: resume it with --task-index {} --task-count {}",
                    path.display(),
                    task.index,
                    task.count,
                    task.index,
                    task.count
                )
                .into());
            }
            let differ = differences(&saved.method, &settings.method);
            if !differ.is_empty() {
                return Err(format!(
                    "{} was made with other settings: {}; resume with the flags the render started with",
                    path.display(),
                    differ.join(", ")
                )
                .into());
            }
            say!(
                "resuming {} after {} paths",
                path.display(),
                checkpoint.samples().map_err(inside)?
            );
            Some(checkpoint)
        }
        None => None,
    };
    let bar = ProgressBar::new(1000).with_style(ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% {msg}",
    )?);
    let observer = Watch {
        bar: bar.clone(),
        args,
        previews: Every::new(args.preview_every)?,
        checkpoints: Every::new(args.checkpoint_every)?,
        checkpoint: Mutex::new(checkpoint_path(args)),
        saved: AtomicBool::new(false),
        failed: AtomicBool::new(false),
        spent: AtomicBool::new(false),
    };
    let start = Instant::now();
    if let Some(task) = args.task() {
        return render_task_with(oracle, &settings, task, resumed.as_ref(), &observer, start);
    }
    let run = |settings: &Settings| match &resumed {
        Some(checkpoint) => resume(oracle, &MaxChannel, settings, checkpoint, &observer),
        None => render(oracle, &MaxChannel, settings, &observer),
    };
    let output = match run(&settings) {
        // The oracle's tempering changes nothing here (an all-diffuse scene):
        // power tempering always does.
        Err(e @ Error::LevelsIndistinguishable { .. }) => {
            warn!("note: {e}; rendering with --tempering power");
            if let Method::Replica(s) = &mut settings.method {
                s.ensemble.tempering = Tempering::Power;
            }
            run(&settings)?
        }
        other => other?,
    };
    bar.finish_and_clear();
    say!(
        "{} {}: {:.2} s",
        args.scene,
        settings.method.name(),
        start.elapsed().as_secs_f64()
    );
    if let Budget::Time(limit) = settings.budget {
        let took = start.elapsed();
        if took > limit.mul_f64(1.1) + Duration::from_millis(200) {
            warn!(
                "note: the render took {:.2} s of a {:.2} s time budget: one unit of its work \
                 ({}) runs whatever the budget, and took longer here; give more time or a \
                 smaller film",
                took.as_secs_f64(),
                limit.as_secs_f64(),
                settings.method.unit_of_work()
            );
        }
    }
    report_extras(&output.extras);
    let ended = if output.cancelled {
        Ended::Stopped(observer.saved())
    } else {
        Ended::Finished
    };
    Ok((Some(output), ended))
}

/// Renders (or resumes) task `task` of the render `settings` describes and
/// writes its partial result to OUT.part once it has finished.
pub(crate) fn render_task_with<O: PathOracle>(
    oracle: &O,
    settings: &Settings,
    task: Task,
    resumed: Option<&Checkpoint>,
    observer: &Watch<'_>,
    start: Instant,
) -> AnyResult<(Option<Output>, Ended)> {
    let args = observer.args;
    let checkpoint = match resumed {
        Some(saved) => {
            if saved.task()? != task {
                return Err(format!(
                    "the checkpoint is of task {} of {}, not of --task-index {} --task-count {}",
                    saved.task()?.index,
                    saved.task()?.count,
                    task.index,
                    task.count
                )
                .into());
            }
            resume_task(oracle, &MaxChannel, settings, saved, observer)?
        }
        None => render_task(oracle, &MaxChannel, settings, task, observer)?,
    };
    observer.bar.finish_and_clear();
    if !checkpoint.finished()? {
        return Ok((None, Ended::Stopped(observer.saved())));
    }
    let part = part_path(&args.out, task);
    if part != output(&args.out, "part") {
        warn!(
            "note: {} holds another task's part (tasks started with one --out): this one goes to {}",
            output(&args.out, "part").display(),
            part.display()
        );
    }
    let bytes = checkpoint_bytes(&checkpoint)?;
    replace(&part, |path| std::fs::write(path, &bytes))?;
    say!(
        "{} {}, task {} of {}: {} paths in {:.2} s; wrote {} ({:.1} MB)",
        args.scene,
        settings.method.name(),
        task.index,
        task.count,
        checkpoint.samples()?,
        start.elapsed().as_secs_f64(),
        part.display(),
        bytes.len() as f64 / 1e6
    );
    Ok((None, Ended::Finished))
}

/// What the method says beyond the image.
pub(crate) fn report_extras(extras: &Extras) {
    match extras {
        Extras::None => {}
        Extras::Replica(r) => {
            let x = &r.exchange;
            let t = r.ladder.temperatures();
            say!(
                "{} chains per ensemble, T = {:.3?}; round trips {}; mean change probability {:.3}",
                t.len(),
                t,
                x.round_trips(),
                x.mean_change_probability()
            );
            let rejection: Vec<String> = x
                .neighbor_rejection()
                .iter()
                .map(|r| format!("{r:.2}"))
                .collect();
            say!(
                "neighbour swap rejection per pair: [{}]; communication barrier {:.2}",
                rejection.join(", "),
                Ladder::barrier(&x.neighbor_rejection())
            );
        }
        Extras::Stratified(extras) => {
            if extras.reconstruction_cut {
                warn!(
                    "note: the time budget ran out during the reconstruction, which kept the \
                     normalizations it had reached (fewer solver iterations)"
                );
            }
            let s = &extras.counters;
            say!(
                "{} sweeps; paths: tiles {}, exchanges {}, regularizer {}, the budget's \
                 remainder {}, initialization {}; tiles started by \
                 global chains {}, borrowing {}, uniform draws {}, never {}; exchanges \
                 accepted {}/{}; pixels that took their MC estimate {}; image scaled by {:.4} \
                 to the MC total",
                s.sweeps,
                s.tile_samples,
                s.exchange_samples,
                s.regularizer_samples,
                s.remainder_samples,
                s.initialization_samples,
                s.initialized_by_global_chains,
                s.initialized_by_borrowing,
                s.initialized_by_uniform_draws,
                s.never_initialized,
                s.exchange_accepted,
                s.exchange_attempts,
                s.fallback_pixels,
                s.total_scale
            );
        }
        Extras::MultiStage(stages) => {
            let grids: Vec<u32> = stages.iter().map(|s| s.grid).collect();
            say!("{} stages, grids {grids:?}", stages.len());
        }
        // A method this command does not know reports nothing more.
        _ => {}
    }
}
