//! The infrastructure bundle adjustment at benchmark size (issue 14): generates the problem
//! once, writes it as text for the Ceres side (`tools/infra_ba_ceres.cc`), solves it with
//! msreg, and evaluates any solved state with msreg's robust cost, so both solvers are
//! judged by one function. Driven by `tools/infra_ba_bench.sh` (docs/benchmarks.md).
//!
//! ```text
//! infra_ba_bench gen <problem.txt> [--keyframes 2000] [--points 50000] [--track 74] [--seed 1]
//! infra_ba_bench solve <problem.txt> <state_out.txt> [--exact] [--tolerance 1e-2] [--products 8]
//! infra_ba_bench eval <problem.txt> <state.txt>...
//! ```
//!
//! The problem: the simulator's building (40 cameras, 153 m loop), keyframes evenly in
//! time along the robot's true motion, ceiling points in a 5 m band over the path, each
//! seen by the keyframes within a horizontal radius chosen so that a track holds `--track`
//! keypoints on average (0.5 px noise, 1 % outliers of 5-20 px); marker corners through
//! each camera's lens at one stamp per keyframe interval (0.3 px, 1 % outliers), the
//! robot pose taken from the true motion at that stamp; blobs of the camera centres within
//! 15 m (1 px). Start: keyframes from a VO-like random walk (0.25 deg and 5 mm per sqrt(m)
//! per axis), points and cameras carried along with the drift of the keyframe that first
//! sees them (plus 1 cm / 0.5 deg noise), `T_F_M` off by 2 cm / 1 deg. The epipolar term
//! is not part of the benchmark.

use anyhow::{bail, Context, Result};
use msreg_estimator::camera::{Camera, Distortion, Projection};
use msreg_host::infra::ba::{robust_cost, BaProblem, BaState, BlobObs, MarkerObs, VoObs};
use msreg_host::infra::ba_solver::{solve_with, Options, Steps};
use msreg_host::infra::io::MarkerDetection;
use msreg_host::infra::scene::{self, RobotMotion, SceneConfig};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::fmt::Write as _;
use std::time::Instant;

/// A generated problem: models, measurements and the start state.
struct Bench {
    f: Camera<f64>,
    cams: Vec<Camera<f64>>,
    corners: [Vector3<f64>; 4],
    vo: Vec<VoObs>,
    markers: Vec<MarkerObs>,
    blobs: Vec<BlobObs>,
    start: BaState,
}

impl Bench {
    /// The problem, its measurements moved out of the bench (~120 MB of keypoints at the
    /// benchmark size, not kept twice).
    fn problem(&mut self) -> BaProblem<'_> {
        BaProblem {
            f: &self.f,
            cams: self.cams.iter().collect(),
            corners: self.corners,
            vo: std::mem::take(&mut self.vo),
            markers: std::mem::take(&mut self.markers),
            blobs: std::mem::take(&mut self.blobs),
            epipolar: Vec::new(),
        }
    }
}

struct GenArgs {
    keyframes: usize,
    points: usize,
    track: f64,
    seed: u64,
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("gen") if args.len() >= 2 => {
            let g = gen_args(&args[2..])?;
            let b = generate(&g);
            std::fs::write(&args[1], write_problem(&b))?;
            println!(
                "keyframes {} points {} cameras {} keypoints {} markers {} blobs {} observations {}",
                b.start.kf.len(),
                b.start.points.len(),
                b.cams.len(),
                b.vo.len(),
                b.markers.len(),
                b.blobs.len(),
                b.vo.len() + 4 * b.markers.len() + b.blobs.len()
            );
            Ok(())
        }
        Some("solve") if args.len() >= 3 => solve(&args[1], &args[2], &solve_options(&args[3..])?),
        Some("eval") if args.len() >= 3 => {
            let mut b = read_problem(&args[1])?;
            let start = b.start.clone();
            let p = b.problem();
            println!("start cost {:.6}", robust_cost(&p, &start).unwrap_or(f64::NAN));
            for path in &args[2..] {
                let s = read_state(path, &start)?;
                let c = robust_cost(&p, &s).context("a projection failed")?;
                println!("{path} cost {c:.6}");
            }
            Ok(())
        }
        _ => bail!("usage: gen <out> [--keyframes N --points N --track T --seed S] | solve <problem> <state_out> [--exact --tolerance T --products N] | eval <problem> <state>..."),
    }
}

fn gen_args(a: &[String]) -> Result<GenArgs> {
    let mut g = GenArgs {
        keyframes: 2000,
        points: 50_000,
        track: 74.0,
        seed: 1,
    };
    for pair in a.chunks(2) {
        let [k, v] = pair else {
            bail!("{pair:?}: option without value")
        };
        match k.as_str() {
            "--keyframes" => g.keyframes = v.parse()?,
            "--points" => g.points = v.parse()?,
            "--track" => g.track = v.parse()?,
            "--seed" => g.seed = v.parse()?,
            _ => bail!("unknown option {k}"),
        }
    }
    Ok(g)
}

/// The solver's options from `solve`'s flags: `--exact` (every step exact), `--tolerance
/// T`, `--products N` (the conjugate-gradient steps' limits).
fn solve_options(a: &[String]) -> Result<Options> {
    let mut o = Options::new(50);
    let mut it = a.iter();
    while let Some(flag) = it.next() {
        let mut value = || it.next().with_context(|| format!("{flag}: no value"));
        match flag.as_str() {
            "--exact" => o.steps = Steps::Exact,
            "--tolerance" => o.pcg_tolerance = value()?.parse()?,
            "--products" => o.pcg_max_products = value()?.parse()?,
            _ => bail!("{flag}: unknown solve option"),
        }
    }
    Ok(o)
}

/// Solves with the options of [`solve_options`] (conjugate-gradient steps by default).
fn solve(problem: &str, out: &str, opts: &Options) -> Result<()> {
    let (t0, c0) = (Instant::now(), cpu_seconds());
    let mut b = read_problem(problem)?;
    let start = b.start.clone();
    let p = b.problem();
    let (t1, c1) = (Instant::now(), cpu_seconds());
    let sol = solve_with(&p, start, *opts).context("BA failed")?;
    let (t2, c2) = (Instant::now(), cpu_seconds());
    std::fs::write(out, write_state(&sol.state))?;
    for (k, it) in sol.trace.iter().enumerate() {
        println!(
            "iteration {} cost {:.6} lambda {:.1e} {} products {} {}",
            k + 1,
            it.cost,
            it.lambda,
            if it.exact { "exact" } else { "cg" },
            it.products,
            if it.accepted { "accepted" } else { "rejected" }
        );
    }
    let t = &sol.timings;
    println!(
        "msreg wall s: structure {:.2} linearise {:.2} eliminate {:.2} factor {:.2} cg {:.2} back {:.2} covariance {:.2}; cpu s: read {:.2} solve {:.2}",
        t.structure, t.linearise, t.eliminate, t.factor, t.pcg, t.back, t.covariance, c1 - c0, c2 - c1
    );
    println!(
        "threads cpu s (user + sys, main first): {}",
        thread_cpu().join(" ")
    );
    println!(
        "msreg read {:.2} s solve {:.2} s iterations {} (rejected {}) exact steps {} cg products {} initial cost {:.6} final cost {:.6}",
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        sol.iterations,
        sol.rejected,
        sol.exact_steps,
        sol.pcg_products,
        sol.initial_cost,
        sol.final_cost
    );
    Ok(())
}

/// CPU time (user + system) of the process so far, all threads.
fn cpu_seconds() -> f64 {
    // SAFETY: `getrusage` only writes the zeroed struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: as above; RUSAGE_SELF is a valid `who`.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return f64::NAN;
    }
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    secs(u.ru_utime) + secs(u.ru_stime)
}

/// CPU time (user + system, seconds) of each thread of the process so far, from
/// `/proc/self/task/*/stat`, the main thread first: with the main thread doing the
/// serial work and the pool's threads the parallel work, `main + max(pool)` estimates the
/// wall time on otherwise idle cores (empty where there is no `/proc`).
fn thread_cpu() -> Vec<String> {
    // SAFETY: `sysconf` only reads a configuration value.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let mut out: Vec<(u64, f64)> = Vec::new();
    for entry in std::fs::read_dir("/proc/self/task")
        .into_iter()
        .flatten()
        .flatten()
    {
        let tid = entry
            .file_name()
            .to_string_lossy()
            .parse::<u64>()
            .unwrap_or(0);
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // Fields after the parenthesised name: state is field 3, utime 14, stime 15.
        let rest = stat.rsplit_once(')').map_or("", |r| r.1);
        let f: Vec<&str> = rest.split_whitespace().collect();
        let ticks = |i: usize| {
            f.get(i - 3)
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(0.0)
        };
        out.push((tid, (ticks(14) + ticks(15)) / hz));
    }
    out.sort_by_key(|t| t.0);
    out.iter().map(|t| format!("{:.2}", t.1)).collect()
}

/// Horizontal visibility radius giving `track` keyframes per point on average for points
/// uniform across a band of half-width `band` (keyframes `spacing` apart).
fn radius_for_track(track: f64, spacing: f64, band: f64) -> f64 {
    let mean = |r: f64| {
        let n = 1000;
        (0..n)
            .map(|i| {
                let d = band * (i as f64 + 0.5) / n as f64;
                2.0 * (r * r - d * d).max(0.0).sqrt() / spacing
            })
            .sum::<f64>()
            / n as f64
    };
    let (mut lo, mut hi) = (0.0, 100.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mean(mid) < track {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

fn perturb(t: &Isometry3<f64>, rot: f64, pos: f64, rng: &mut ChaCha8Rng) -> Isometry3<f64> {
    let n = Normal::new(0.0, 1.0).expect("unit normal");
    let w = Vector3::from_fn(|_, _| n.sample(rng) * rot);
    let p = Vector3::from_fn(|_, _| n.sample(rng) * pos);
    Isometry3::from_parts(
        Translation3::from(t.translation.vector + p),
        t.rotation * UnitQuaternion::from_scaled_axis(w),
    )
}

/// Pixel + Gaussian noise, 1 % of them displaced by 5-20 px.
fn noisy(px: Vector2<f64>, sigma: f64, rng: &mut ChaCha8Rng) -> Vector2<f64> {
    let n = Normal::new(0.0, sigma).expect("sigma > 0");
    let mut out = px + Vector2::new(n.sample(rng), n.sample(rng));
    if rng.gen_bool(0.01) {
        let a = rng.gen_range(0.0..std::f64::consts::TAU);
        out += Vector2::new(a.cos(), a.sin()) * rng.gen_range(5.0..20.0);
    }
    out
}

fn generate(g: &GenArgs) -> Bench {
    let mut rng = ChaCha8Rng::seed_from_u64(g.seed);
    let scene_cfg = SceneConfig::default();
    let motion = RobotMotion::new(&scene_cfg);
    let cams_truth = scene::infra_cameras(&scene_cfg, motion.path(), &mut rng);
    let f = scene::robot_fisheye();
    let dt = motion.duration_s / (g.keyframes - 1) as f64;
    let stamps: Vec<f64> = (0..g.keyframes).map(|k| k as f64 * dt).collect();
    let truth: Vec<Isometry3<f64>> = stamps.iter().map(|&t| motion.pose(t)).collect();
    let band = 2.5;
    let radius = radius_for_track(g.track, motion.path().length() / g.keyframes as f64, band);
    let points: Vec<Vector3<f64>> = (0..g.points)
        .map(|_| {
            let (p, d) = motion.path().at(rng.gen_range(0.0..motion.path().length()));
            let q = p + Vector2::new(-d.y, d.x) * rng.gen_range(-band..band);
            Vector3::new(q.x, q.y, scene_cfg.ceiling_z)
        })
        .collect();
    let vo = keypoints(&f, &truth, &points, radius, &mut rng);
    let t_f_m = Isometry3::from_parts(
        Translation3::new(-0.30, 0.05, 0.08),
        UnitQuaternion::from_euler_angles(2f64.to_radians(), -1f64.to_radians(), 1.3),
    );
    let corners = [(-0.25, 0.25), (0.25, 0.25), (0.25, -0.25), (-0.25, -0.25)]
        .map(|(x, y)| Vector3::new(x, y, 0.0));
    let cams: Vec<Camera<f64>> = cams_truth.iter().map(|c| c.camera).collect();
    let poses: Vec<Isometry3<f64>> = cams_truth.iter().map(|c| c.t_world_cam).collect();
    let markers = marker_obs(&cams, &poses, &motion, &stamps, &t_f_m, &corners, &mut rng);
    let blobs = blob_obs(&f, &truth, &poses, &mut rng);
    let start = start_state(&truth, &points, &vo, &poses, &markers, &t_f_m, &mut rng);
    Bench {
        f,
        cams,
        corners,
        vo,
        markers,
        blobs,
        start,
    }
}

fn keypoints(
    f: &Camera<f64>,
    truth: &[Isometry3<f64>],
    points: &[Vector3<f64>],
    radius: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<VoObs> {
    let mut vo = Vec::new();
    for (j, x) in points.iter().enumerate() {
        for (k, t) in truth.iter().enumerate() {
            if (t.translation.vector - x).xy().norm() > radius {
                continue;
            }
            let Some(pr) = f.project(&t.inverse_transform_point(&Point3::from(*x)).coords) else {
                continue;
            };
            if f.in_image(&pr.pixel, 1.0) {
                let uv = noisy(pr.pixel, 0.5, rng);
                vo.push(VoObs {
                    kf: k,
                    point: j,
                    uv,
                });
            }
        }
    }
    vo
}

fn marker_obs(
    cams: &[Camera<f64>],
    poses: &[Isometry3<f64>],
    motion: &RobotMotion,
    stamps: &[f64],
    t_f_m: &Isometry3<f64>,
    corners: &[Vector3<f64>; 4],
    rng: &mut ChaCha8Rng,
) -> Vec<MarkerObs> {
    let mut out = Vec::new();
    for (c, (cam, pose)) in cams.iter().zip(poses).enumerate() {
        for i in 0..stamps.len() - 1 {
            let alpha: f64 = rng.gen_range(0.0..1.0);
            let t = stamps[i] + alpha * (stamps[i + 1] - stamps[i]);
            let t_c_m = pose.inverse() * motion.pose(t) * t_f_m;
            let normal = t_c_m.rotation * Vector3::z();
            if normal.dot(&t_c_m.translation.vector.normalize()) > -(15f64.to_radians().sin()) {
                continue;
            }
            let px: Option<Vec<Vector2<f64>>> = corners
                .iter()
                .map(|x| {
                    let p = cam.project(&(t_c_m * Point3::from(*x)).coords)?.pixel;
                    cam.in_image(&p, 3.0).then_some(p)
                })
                .collect();
            let Some(px) = px else { continue };
            if (px[0] - px[1]).norm() < 10.0 {
                continue;
            }
            let detection = MarkerDetection {
                stamp_ns: (t * 1e9) as u64,
                marker_id: 7,
                corners: [0, 1, 2, 3].map(|k| noisy(px[k], 0.3, rng)),
            };
            out.push(MarkerObs {
                cam: c,
                i,
                j: i + 1,
                alpha,
                detection,
            });
        }
    }
    out
}

fn blob_obs(
    f: &Camera<f64>,
    truth: &[Isometry3<f64>],
    poses: &[Isometry3<f64>],
    rng: &mut ChaCha8Rng,
) -> Vec<BlobObs> {
    let n = Normal::new(0.0, 1.0).expect("sigma");
    let mut out = Vec::new();
    for (k, t) in truth.iter().enumerate() {
        for (c, pose) in poses.iter().enumerate() {
            let x = pose.translation.vector;
            if (x - t.translation.vector).norm() > 15.0 || !rng.gen_bool(0.95) {
                continue;
            }
            let Some(pr) = f.project(&t.inverse_transform_point(&Point3::from(x)).coords) else {
                continue;
            };
            if f.in_image(&pr.pixel, 1.0) {
                let uv = pr.pixel + Vector2::new(n.sample(rng), n.sample(rng));
                out.push(BlobObs { kf: k, cam: c, uv });
            }
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn start_state(
    truth: &[Isometry3<f64>],
    points: &[Vector3<f64>],
    vo: &[VoObs],
    cams: &[Isometry3<f64>],
    markers: &[MarkerObs],
    t_f_m: &Isometry3<f64>,
    rng: &mut ChaCha8Rng,
) -> BaState {
    let mut kf = vec![truth[0]];
    for k in 1..truth.len() {
        let rel = truth[k - 1].inverse() * truth[k];
        let d = rel.translation.vector.norm().max(1e-6).sqrt();
        let noisy_rel = perturb(&rel, 0.25f64.to_radians() * d, 0.005 * d, rng);
        kf.push(kf[k - 1] * noisy_rel);
    }
    let drift = |k: usize| kf[k] * truth[k].inverse();
    let mut first = vec![usize::MAX; points.len()];
    for o in vo {
        first[o.point] = first[o.point].min(o.kf);
    }
    let n = Normal::new(0.0, 0.01).expect("sigma");
    let pts = points
        .iter()
        .zip(&first)
        .map(|(x, &k)| {
            let d = drift(k.min(truth.len() - 1));
            (d * Point3::from(*x)).coords + Vector3::from_fn(|_, _| n.sample(rng))
        })
        .collect();
    let cam_start = cams
        .iter()
        .enumerate()
        .map(|(c, pose)| {
            let k = markers.iter().find(|m| m.cam == c).map_or(0, |m| m.i);
            perturb(&(drift(k) * pose), 0.5f64.to_radians(), 0.01, rng)
        })
        .collect();
    BaState {
        kf,
        cams: cam_start,
        t_f_m: perturb(t_f_m, 1f64.to_radians(), 0.02, rng),
        points: pts,
    }
}

// ---- text format -------------------------------------------------------------------

fn pose_line(out: &mut String, t: &Isometry3<f64>) {
    let q = t.rotation.quaternion();
    let p = t.translation.vector;
    let _ = writeln!(
        out,
        "{} {} {} {} {} {} {}",
        q.w, q.i, q.j, q.k, p.x, p.y, p.z
    );
}

fn camera_line(out: &mut String, c: &Camera<f64>) {
    let i = c.intrinsics();
    let (kind, d) = match (c.projection(), c.distortion()) {
        (Projection::Pinhole, Distortion::Equidistant(e)) => (0, [e.k1, e.k2, e.k3, e.k4]),
        (Projection::Pinhole, Distortion::RadTan(r)) => (1, [r.k1, r.k2, r.p1, r.p2]),
        _ => (2, [0.0; 4]),
    };
    let (w, h) = c.resolution;
    let _ = writeln!(
        out,
        "{kind} {w} {h} {} {} {} {} {} {} {} {}",
        i.fu, i.fv, i.cu, i.cv, d[0], d[1], d[2], d[3]
    );
}

fn write_state(s: &BaState) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{} {} {}", s.kf.len(), s.cams.len(), s.points.len());
    for t in s.kf.iter().chain(&s.cams).chain([&s.t_f_m]) {
        pose_line(&mut out, t);
    }
    for x in &s.points {
        let _ = writeln!(out, "{} {} {}", x.x, x.y, x.z);
    }
    out
}

fn write_problem(b: &Bench) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{} {} {} {} {} {}",
        b.start.kf.len(),
        b.start.points.len(),
        b.cams.len(),
        b.vo.len(),
        b.markers.len(),
        b.blobs.len()
    );
    camera_line(&mut out, &b.f);
    for c in &b.cams {
        camera_line(&mut out, c);
    }
    for x in &b.corners {
        let _ = writeln!(out, "{} {} {}", x.x, x.y, x.z);
    }
    out.push_str(&write_state(&b.start));
    for o in &b.vo {
        let _ = writeln!(out, "{} {} {} {}", o.kf, o.point, o.uv.x, o.uv.y);
    }
    for m in &b.markers {
        let c = &m.detection.corners;
        let _ = write!(out, "{} {} {} {}", m.cam, m.i, m.j, m.alpha);
        for p in c {
            let _ = write!(out, " {} {}", p.x, p.y);
        }
        out.push('\n');
    }
    for o in &b.blobs {
        let _ = writeln!(out, "{} {} {} {}", o.kf, o.cam, o.uv.x, o.uv.y);
    }
    out
}

/// Whitespace-separated numbers of a text file, in order.
struct Tokens {
    path: String,
    /// The numbers, parsed in pieces (kept apart: one more copy of ~120 MB at the
    /// benchmark size otherwise).
    words: std::iter::Flatten<std::vec::IntoIter<Vec<f64>>>,
}

impl Tokens {
    fn read(path: &str) -> Result<Self> {
        use rayon::prelude::*;
        let bytes = std::fs::read(path).with_context(|| format!("reading {path}"))?;
        // Parsed in parallel (UTF-8 check included), in pieces cut at whitespace.
        let pieces = 8 * rayon::current_num_threads();
        let mut cuts = vec![0];
        for k in 1..pieces {
            let at = (bytes.len() * k / pieces).max(*cuts.last().unwrap_or(&0));
            let end = bytes[at..]
                .iter()
                .position(u8::is_ascii_whitespace)
                .map_or(bytes.len(), |i| at + i);
            cuts.push(end);
        }
        cuts.push(bytes.len());
        let parts = cuts
            .par_windows(2)
            .map(|c| {
                let text = std::str::from_utf8(&bytes[c[0]..c[1]]).map_err(|e| e.to_string())?;
                text.split_ascii_whitespace()
                    .map(|w| w.parse::<f64>().map_err(|e| format!("{w:?}: {e}")))
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<Vec<_>, String>>()
            .map_err(|e| anyhow::anyhow!("{path}: not a number: {e}"))?;
        Ok(Self {
            path: path.into(),
            words: parts.into_iter().flatten(),
        })
    }
    fn next(&mut self) -> Result<f64> {
        self.words
            .next()
            .with_context(|| format!("{}: ends early", self.path))
    }
    fn index(&mut self) -> Result<usize> {
        Ok(self.next()? as usize)
    }
    fn pose(&mut self) -> Result<Isometry3<f64>> {
        let q = nalgebra::Quaternion::new(self.next()?, self.next()?, self.next()?, self.next()?);
        let p = Vector3::new(self.next()?, self.next()?, self.next()?);
        Ok(Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_quaternion(q),
        ))
    }
    fn vec3(&mut self) -> Result<Vector3<f64>> {
        Ok(Vector3::new(self.next()?, self.next()?, self.next()?))
    }
    fn camera(&mut self) -> Result<Camera<f64>> {
        let (kind, w, h) = (self.index()?, self.index()?, self.index()?);
        let i = msreg_estimator::camera::Intrinsics {
            fu: self.next()?,
            fv: self.next()?,
            cu: self.next()?,
            cv: self.next()?,
        };
        let d = [self.next()?, self.next()?, self.next()?, self.next()?];
        let dist = match kind {
            0 => Distortion::Equidistant(msreg_estimator::camera::equidistant::Equidistant {
                k1: d[0],
                k2: d[1],
                k3: d[2],
                k4: d[3],
            }),
            1 => Distortion::RadTan(msreg_estimator::camera::radtan::RadTan {
                k1: d[0],
                k2: d[1],
                p1: d[2],
                p2: d[3],
                k3: 0.0,
            }),
            _ => bail!("{}: camera kind {kind}", self.path),
        };
        Camera::new(Projection::Pinhole, i, dist, (w as u32, h as u32))
            .map_err(|e| anyhow::anyhow!("{}: {e:?}", self.path))
    }
    fn state(&mut self) -> Result<BaState> {
        let (nk, nc, np) = (self.index()?, self.index()?, self.index()?);
        let kf = (0..nk).map(|_| self.pose()).collect::<Result<_>>()?;
        let cams = (0..nc).map(|_| self.pose()).collect::<Result<_>>()?;
        let t_f_m = self.pose()?;
        let points = (0..np).map(|_| self.vec3()).collect::<Result<_>>()?;
        Ok(BaState {
            kf,
            cams,
            t_f_m,
            points,
        })
    }
}

fn read_problem(path: &str) -> Result<Bench> {
    let mut t = Tokens::read(path)?;
    let n: Vec<usize> = (0..6).map(|_| t.index()).collect::<Result<_>>()?;
    let f = t.camera()?;
    let cams = (0..n[2]).map(|_| t.camera()).collect::<Result<Vec<_>>>()?;
    let corners = [t.vec3()?, t.vec3()?, t.vec3()?, t.vec3()?];
    let start = t.state()?;
    let mut vo = Vec::with_capacity(n[3]);
    for _ in 0..n[3] {
        let (kf, point) = (t.index()?, t.index()?);
        let uv = Vector2::new(t.next()?, t.next()?);
        vo.push(VoObs { kf, point, uv });
    }
    let mut markers = Vec::with_capacity(n[4]);
    for _ in 0..n[4] {
        let (cam, i, j, alpha) = (t.index()?, t.index()?, t.index()?, t.next()?);
        let mut c = [Vector2::zeros(); 4];
        for x in &mut c {
            *x = Vector2::new(t.next()?, t.next()?);
        }
        let detection = MarkerDetection {
            stamp_ns: 0,
            marker_id: 7,
            corners: c,
        };
        markers.push(MarkerObs {
            cam,
            i,
            j,
            alpha,
            detection,
        });
    }
    let mut blobs = Vec::with_capacity(n[5]);
    for _ in 0..n[5] {
        let (kf, cam) = (t.index()?, t.index()?);
        let uv = Vector2::new(t.next()?, t.next()?);
        blobs.push(BlobObs { kf, cam, uv });
    }
    Ok(Bench {
        f,
        cams,
        corners,
        vo,
        markers,
        blobs,
        start,
    })
}

fn read_state(path: &str, like: &BaState) -> Result<BaState> {
    let s = Tokens::read(path)?.state()?;
    if s.kf.len() != like.kf.len() || s.cams.len() != like.cams.len() {
        bail!("{path}: state does not match the problem");
    }
    Ok(s)
}
