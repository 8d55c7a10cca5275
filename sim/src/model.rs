//! The sensor model and the ray tracer of one accretion (thesis §3.2, §5.3).

use glam::{DVec2, DVec3};
use rand_pcg::Pcg32;

use crate::bubbles::{BubbleLanes, BubbleRay, GapSampler, land_scattered};
pub use crate::config::{
    Coupling, DiffuseFresnel, IceKind, IceParams, SensorKind, SimConfig, SimError,
};
use crate::consts::*;
pub use crate::curve::{Curve, CurvePoint};
use crate::kernels::{DiffuseLanes, DiffuseRay, reflect_diffuse, specular_slots};
use crate::laws::{fr_dielectric, fresnel_transmittance, refract, theta_max, theta_max_fibre};
use crate::streams::{
    CounterStream, STREAM_ACCRETION, accretion_key, bubble_stream, diffuse_stream, fill_u32,
    geometric_gap, mix64, std_normal, uniform, uniform32, unit_circle_unnormalised,
};

/// One source fibre's ray, fixed at model set-up.
#[derive(Clone, Copy, Debug)]
struct SourceRay {
    /// Position on the face, mm.
    p0: DVec2,
    /// Direction in the medium (unit, z > 0).
    dir: DVec3,
    /// Flux that enters the medium: Φ_ray · T(fibre→medium), W.
    flux_in_w: f64,
    /// Flux reflected at a dry fibre/air face, W (Sensor A leak).
    refl_air_w: f64,
    /// Flux reflected at the fibre/medium face, W (Sensor A leak under ice).
    refl_med_w: f64,
}

/// The sensor with its fibres set up: trace accretions with it.
#[derive(Clone, Debug)]
pub struct SensorModel {
    cfg: SimConfig,
    rays: Vec<SourceRay>,
    thick: Vec<f64>,
    /// Unit vector along the signal fibres' axis (pointing into the medium).
    fibre_axis: DVec3,
    cos_accept: f64,
    /// Dense bubbles (rime) walk gap by gap from counter-based streams (bubbles.rs).
    dense: Option<GapSampler>,
}

/// Most bubble layers one ray walks through (20 000 × 0.1 mm = 2 m of ice along z).
const MAX_LAYERS_PER_RAY: u32 = 20_000;

/// Above this P_B the bubbles are walked by `bubbles::GapSampler` from counter-based
/// streams; at or below it by `geometric_gap` (one `ln` per bubble) from a PCG stream.
const DENSE_ABOVE: f64 = 0.02;

/// The number of bubble layers a ray meets within the output thicknesses: the first layer j
/// whose q(j) (its thickness in output steps, non-decreasing in j) lies beyond the last
/// output index, at most `MAX_LAYERS_PER_RAY`. Layer j is frozen in at the first index
/// i ≥ `first_wet` with i ≥ q(j); j_end is the first layer for which that index is ≥ `nt`.
fn layers_covered(q_of: &impl Fn(u32) -> f64, first_wet: usize, nt: usize) -> u32 {
    if first_wet >= nt {
        return 0;
    }
    let last = (nt - 1) as f64;
    let beyond = |j: u32| q_of(j) > last;
    // q is linear in j up to rounding: start from the straight-line estimate, then settle
    // on the exact first j with the same comparisons as a walk layer by layer.
    let (q0, q1) = (q_of(0), q_of(1));
    let slope = q1 - q0;
    let mut j = if slope > 0.0 {
        ((last - q0) / slope).clamp(0.0, MAX_LAYERS_PER_RAY as f64) as u32
    } else {
        0
    };
    while j > 0 && beyond(j - 1) {
        j -= 1;
    }
    while j < MAX_LAYERS_PER_RAY && !beyond(j) {
        j += 1;
    }
    j
}

/// The smallest integer i ≥ 0 with i ≥ q, as an index (q ≤ `usize::MAX`): ceil without a
/// libm call. Exact: `i as f64 >= q` and `(i - 1) as f64 < q` for every finite q.
#[inline]
fn ceil_index(q: f64) -> usize {
    let t = q as i64; // toward zero: the ceiling for q ≤ 0, the floor for q > 0
    let t = if (t as f64) < q { t + 1 } else { t };
    t.max(0) as usize
}

impl SensorModel {
    /// Set up the sensor: source fibres on their grid, fibre angles θ_f ~ N(0, θ_max/5)
    /// clipped to ±θ_max,f with a uniform azimuth (eqs. 3.17–3.20), drawn from `fibre_seed`.
    ///
    /// # Panics
    /// If `cfg.validate()` fails (e.g. a zero step): check user input with `validate` first.
    pub fn new(cfg: &SimConfig) -> Self {
        if let Err(e) = cfg.validate() {
            panic!("invalid SimConfig: {e}");
        }
        let n_med = cfg.params.n_medium;
        let th_max = theta_max(NA, N_AIR); // (3.17)
        let th_max_f = theta_max_fibre(th_max, N_AIR, N_FIBRE); // (3.18)
        let sigma = th_max / 5.0;
        let grid = cfg.geometry.source_grid_mm();
        let flux_ray = SOURCE_FLUX_W / grid.len() as f64;
        let mut rng = Pcg32::new(mix64(cfg.fibre_seed), 1);
        let incl = INCLINATION_DEG.to_radians();
        let (si, ci) = incl.sin_cos();
        let face_in = DVec3::new(0.0, 0.0, -1.0); // normal on the fibre side
        let rays = grid
            .into_iter()
            .map(|(x, y)| {
                let (th_f, beta) = if cfg.fibre_spread {
                    let th = (sigma * std_normal(&mut rng)).clamp(-th_max_f, th_max_f);
                    (th, std::f64::consts::TAU * uniform(&mut rng))
                } else {
                    (0.0, 0.0)
                };
                // Direction inside an upright fibre (Fig. 3.15) ...
                let (st, ct) = th_f.sin_cos();
                let f = DVec3::new(st * beta.cos(), st * beta.sin(), ct);
                // ... turned toward +x by the inclination about y: eq. 3.20 in 3-D
                // (θ_i,x = θ_f,x + θ_Incl for rays in the x–z plane).
                let fi = DVec3::new(f.x * ci + f.z * si, f.y, -f.x * si + f.z * ci);
                let cos_i = fi.z;
                let (dir, t) = match refract(fi, face_in, N_FIBRE, n_med) {
                    Some(d) => (d, fresnel_transmittance(cos_i, N_FIBRE, n_med)),
                    None => (DVec3::Z, 0.0),
                };
                SourceRay {
                    p0: DVec2::new(x, y),
                    dir,
                    flux_in_w: flux_ray * t,
                    refl_air_w: flux_ray * fr_dielectric(cos_i, N_FIBRE, N_AIR),
                    refl_med_w: flux_ray * fr_dielectric(cos_i, N_FIBRE, n_med),
                }
            })
            .collect();
        SensorModel {
            cfg: cfg.clone(),
            rays,
            thick: cfg.thicknesses_mm(),
            fibre_axis: DVec3::new(si, 0.0, ci),
            cos_accept: th_max_f.cos(),
            dense: (cfg.params.p_bubble > DENSE_ABOVE)
                .then(|| GapSampler::new(cfg.params.p_bubble)),
        }
    }

    /// Number of source rays.
    pub fn n_rays(&self) -> usize {
        self.rays.len()
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Number of ray evaluations (rays × thicknesses) of one accretion.
    pub fn ray_evaluations(&self) -> u64 {
        self.rays.len() as u64 * self.thick.len() as u64
    }

    /// Fraction of a downward ray (direction `s`, s.z < 0) that enters a signal fibre
    /// (eqs. 3.24–3.25 with the Fresnel transmittance, plus the optional acceptance cone).
    #[inline]
    fn couple(&self, s: DVec3) -> f64 {
        let n_med = self.cfg.params.n_medium;
        let cos_i = -s.z;
        let t = fresnel_transmittance(cos_i, n_med, N_FIBRE);
        match self.cfg.coupling {
            Coupling::ThesisLiteral => t,
            Coupling::AcceptanceCone if self.in_acceptance_cone(s) => t,
            Coupling::AcceptanceCone => 0.0,
        }
    }

    /// Whether a downward ray `s` refracted into a signal fibre lies inside its guided cone
    /// (θ_max,f, eq. 3.18, around the fibre axis): `Coupling::AcceptanceCone`.
    fn in_acceptance_cone(&self, s: DVec3) -> bool {
        match refract(s, DVec3::Z, self.cfg.params.n_medium, N_FIBRE) {
            Some(tr) => tr.dot(-self.fibre_axis) >= self.cos_accept,
            None => false,
        }
    }

    /// Trace one accretion: one physical ice body grown from 0 to `max_mm`, deterministic
    /// in (seed, run). Cost O(rays × (thicknesses + bubbles)).
    // The thickness index addresses several arrays at once (thicknesses, sums, bubble steps).
    #[allow(clippy::needless_range_loop)]
    pub fn accretion(&self, seed: u64, run: u64) -> Curve {
        let cfg = &self.cfg;
        let p = cfg.params;
        let geo = cfg.geometry;
        let cx = geo.centre_x_mm();
        let n_med = p.n_medium;
        let alpha = ALPHA_PER_MM;
        let key = accretion_key(seed, run);
        let mut acc = Pcg32::new(key, STREAM_ACCRETION);
        let sx = p.slope_max_rad * (2.0 * uniform(&mut acc) - 1.0);
        let sy = p.slope_max_rad * (2.0 * uniform(&mut acc) - 1.0);
        let (tx, ty) = (sx.tan(), sy.tan());
        let normal = DVec3::new(-tx, -ty, 1.0).normalize();
        let nt = self.thick.len();
        // Reflected flux per thickness and bundle.
        let mut refl = vec![[0.0f64; 2]; nt];
        let mut scat_delta = vec![[0.0f64; 2]; nt];
        let mut leak = vec![0.0f64; nt];
        let ln_q = if p.p_bubble > 0.0 {
            (1.0 - p.p_bubble).ln()
        } else {
            0.0
        };
        let diffuse = p.diffuse_max_rad > 0.0;
        let mut lanes = BubbleLanes::default();
        // F^n, n = 0, 1, …: grown to the most bubbles one ray met.
        let mut forward_pow: Vec<f64> = vec![1.0];
        let mut landed: Vec<u32> = Vec::new();
        let mut spec_slot: Vec<i32> = Vec::with_capacity(nt);
        let sensor_a = cfg.sensor == SensorKind::A;
        let bundles = geo.bundles();
        // Bounding box of the face, for culling scattered rays.
        let (x_lo, x_hi, y_hi) = (
            -geo.radius_mm(),
            geo.length_b_mm() + geo.radius_mm(),
            geo.radius_mm(),
        );
        let first_wet = self.thick.iter().position(|&d| d > 0.0).unwrap_or(nt);
        let inv_step = 1.0 / cfg.step_mm;
        // The circle around the bundles (0 ≤ x ≤ B + R, |y| ≤ R): a reflection that lands
        // farther than `face_radius` from `face_centre` misses them.
        let face_centre = DVec2::new(0.5 * x_hi, 0.0);
        let face_radius = face_centre.x.hypot(y_hi);

        // Per ray: the forward flux after n bubbles (fwd_after[n]) and, at each thickness
        // index where bubbles are frozen in, how many are frozen in up to it (`frozen_by`,
        // 0 at the other indices: the bubbles are frozen in in walk order, so the number
        // frozen in at indices ≤ i is the running maximum). The forward flux at thickness i
        // is fwd_after[that number].
        let mut fwd_after: Vec<f64> = Vec::with_capacity(256);
        let mut frozen_by = vec![0u32; nt];
        let mut diffuse_draws: Vec<u32> = Vec::with_capacity(nt);
        let mut diffuse_out = DiffuseLanes::default();
        let mut diffuse_bubbles: Vec<usize> = Vec::with_capacity(nt);
        for (r, ray) in self.rays.iter().enumerate() {
            if sensor_a {
                for l in leak.iter_mut().take(first_wet) {
                    *l += ray.refl_air_w;
                }
            }
            let v = ray.dir;
            let a = tx * (ray.p0.x - cx) + ty * ray.p0.y;
            let den = v.z - tx * v.x - ty * v.y;
            if ray.flux_in_w <= 0.0 || den <= 1e-9 {
                continue;
            }
            let slope_xy = DVec2::new(v.x, v.y) / v.z;
            // Pass 1, bubbles: layer j (z from jΔ to (j+1)Δ, bubble at its middle) is frozen
            // in once the local surface above the bubble is at least (j+1)Δ high, i.e. from
            // the mean thickness d_j = (j+1)Δ − off(z_b), where off is the plane's local
            // offset at the bubble. d_j grows with j (the ray is steeper than the plane:
            // den > 0), so the forward flux at each thickness is a running product, stored
            // as fwd_after[n] and, per index, the number of bubbles frozen in up to it.
            let off1 = tx * slope_xy.x + ty * slope_xy.y;
            let bray = BubbleRay {
                p0: ray.p0,
                slope_xy,
                a,
                off1,
                inv_step,
                first_wet: first_wet as u32,
            };
            // q(j): d_j in output steps; layer j belongs to the first output index ≥ q(j).
            let q_of = |j: u32| bray.cover_steps(f64::from(j));
            // The layers that the ice covers within max_mm: j < j_end. Beyond, the bubbles
            // are not drawn. A ray almost parallel to a tilted surface would walk very many
            // layers before the surface covers them: at most MAX_LAYERS_PER_RAY (2 m).
            let j_end = if p.p_bubble > 0.0 {
                layers_covered(&q_of, first_wet, nt)
            } else {
                0
            };
            fwd_after.clear();
            fwd_after.push(ray.flux_in_w);
            let mut fwd = ray.flux_in_w;
            // The scattered part of a bubble: 5 % deflected toward the face (Fig. 3.11),
            // attenuated along the ray up to the bubble and down to the face (Beer–Lambert,
            // eq. 3.21), entering the bundle with the coupling of eqs. 3.24–3.25.
            let mut scatter = |i: usize, k: usize, fwd: f64, s: DVec3, z_b: f64, reach: f64| {
                let path = z_b / v.z + reach;
                scat_delta[i][k] +=
                    fwd * (1.0 - FORWARD_FRACTION) * self.couple(s) * (-alpha * path).exp();
            };
            if let Some(gaps) = &self.dense {
                // Dense bubbles (rime): the walk draws one geometric gap per bubble from a
                // counter-based stream, then lands all scattered rays at once (bubbles.rs).
                lanes.walk(CounterStream::new(key, bubble_stream(r)), gaps, j_end);
                land_scattered(&bray, &bundles, &mut lanes);
                let count = lanes.len();
                // Forward flux after n bubbles: Φ·F^n (F = FORWARD_FRACTION).
                while forward_pow.len() <= count {
                    let last = forward_pow.last().copied().unwrap_or(1.0);
                    forward_pow.push(last * FORWARD_FRACTION);
                }
                fwd_after.extend(forward_pow[1..=count].iter().map(|&f| ray.flux_in_w * f));
                let m = lanes.tally(&mut frozen_by, &mut landed);
                for &n in &landed[..m] {
                    let n = n as usize;
                    let sc = lanes.scattered(n);
                    let (i, k) = (lanes.index[n] as usize, lanes.slot[n] as usize);
                    scatter(
                        i,
                        k,
                        fwd_after[n],
                        DVec3::from(sc.dir),
                        sc.z_mm,
                        sc.reach_mm,
                    );
                }
            } else {
                // Sparse bubbles (glazed): geometric gaps between bubbles by inversion
                // (one `ln` per bubble), P_B per layer; each bubble's scattered ray is
                // culled before its azimuth is drawn when it cannot reach the face.
                let mut bub = Pcg32::new(key, bubble_stream(r));
                let mut j: u32 = if p.p_bubble > 0.0 {
                    geometric_gap(&mut bub, ln_q)
                } else {
                    j_end
                };
                while j < j_end {
                    let z_b = (j as f64 + 0.5) * BUBBLE_LAYER_MM;
                    // First output index at or above d_j (j < j_end: below nt).
                    let i = ceil_index(q_of(j)).max(first_wet);
                    let b = ray.p0 + slope_xy * z_b;
                    let cos_b = 1.0 - uniform32(&mut bub); // isotropic over the lower hemisphere
                    let sin2_b = (1.0 - cos_b * cos_b).max(0.0);
                    // Horizontal travel z_b·tan θ_B; beyond the farthest point of the face
                    // the ray misses whatever its azimuth, so the azimuth is not drawn.
                    let far_x = (b.x - x_lo).abs().max((b.x - x_hi).abs());
                    let far_y = b.y.abs() + y_hi;
                    let travel2 = z_b * z_b * sin2_b / (cos_b * cos_b);
                    if travel2 <= far_x * far_x + far_y * far_y {
                        let (ua, ub, uq) = unit_circle_unnormalised(&mut bub);
                        let norm = uq.sqrt().recip();
                        let (c_phi, s_phi) = (ua * norm, ub * norm);
                        let sin_b = sin2_b.sqrt();
                        let reach = z_b / cos_b;
                        let land = b + DVec2::new(c_phi, s_phi) * (sin_b * reach);
                        let k = bundles.slot(land.x, land.y);
                        if k < 2 {
                            let s = DVec3::new(sin_b * c_phi, sin_b * s_phi, -cos_b);
                            scatter(i, k, fwd, s, z_b, reach);
                        }
                    }
                    fwd *= FORWARD_FRACTION;
                    fwd_after.push(fwd);
                    frozen_by[i] = (fwd_after.len() - 1) as u32;
                    let gap = geometric_gap(&mut bub, ln_q);
                    j = j.saturating_add(1).saturating_add(gap);
                }
            }
            let had_bubbles = fwd_after.len() > 1;

            // Pass 2, the surface at every thickness.
            if sensor_a {
                for (i, l) in leak.iter_mut().enumerate().skip(first_wet) {
                    *l += if self.thick[i] + a <= 0.0 {
                        ray.refl_air_w
                    } else {
                        ray.refl_med_w
                    };
                }
            }
            if diffuse {
                // The surface is above the fibre (h0 = d + a > 0) from index i0 on: one
                // diffuse angle is drawn per such thickness, in order. The reflected rays of
                // all of them are traced at once, then added in order.
                let i0 = (first_wet..nt)
                    .find(|&i| self.thick[i] + a > 0.0)
                    .unwrap_or(nt);
                let dray = DiffuseRay {
                    v,
                    normal,
                    p0: [ray.p0.x, ray.p0.y],
                    a,
                    den,
                    diffuse_max_rad: p.diffuse_max_rad,
                    facet_fresnel: cfg.diffuse_fresnel == DiffuseFresnel::Facet,
                    n_medium: n_med,
                    n_air: N_AIR,
                    n_fibre: N_FIBRE,
                    alpha_per_mm: alpha,
                };
                // Beyond a thickness that depends on the ray no diffuse angle brings the
                // reflection back onto the face: those thicknesses are not traced, nor their
                // angles drawn (the draws are the stream's first ones, in order).
                let reach = (ray.p0 - face_centre).length() + face_radius;
                let h0_max = dray.h0_cutoff_mm(reach);
                let i_end = i0 + self.thick[i0..nt].partition_point(|&d| d + a <= h0_max);
                diffuse_draws.resize(i_end - i0, 0);
                fill_u32(key, diffuse_stream(r), &mut diffuse_draws);
                reflect_diffuse(
                    &dray,
                    &bundles,
                    &self.thick[i0..i_end],
                    &diffuse_draws,
                    &mut diffuse_out,
                );
                // The bubbles frozen in up to each landed thickness: a running maximum
                // (`frozen_by`), needed only when the ray met bubbles.
                let n_bub0 = frozen_before(&frozen_by[first_wet..i0]);
                if had_bubbles {
                    diffuse_bubbles.clear();
                    diffuse_bubbles.extend(frozen_by[i0..i_end].iter().scan(n_bub0, |m, &f| {
                        *m = (*m).max(f as usize);
                        Some(*m)
                    }));
                }
                let cone = cfg.coupling == Coupling::AcceptanceCone;
                let d = &diffuse_out;
                for (&n, &w) in d.landed.iter().zip(&d.weight) {
                    let n = n as usize;
                    let dir = DVec3::new(d.dir[0][n], d.dir[1][n], d.dir[2][n]);
                    if cone && !self.in_acceptance_cone(dir) {
                        continue;
                    }
                    let fwd = if had_bubbles {
                        fwd_after[diffuse_bubbles[n]]
                    } else {
                        fwd_after[n_bub0]
                    };
                    refl[i0 + n][d.slot[n] as usize] += fwd * w;
                }
            } else if let Some((rfl, rd)) = reflect_setup(v, normal, n_med) {
                // Specular reflection, fixed per accretion: the landing point moves on a
                // line, land(d) = p0 + w·(d + a), so only the thicknesses whose landing
                // point lies in the face's bounding box are visited (the bundles are convex,
                // their union too): cost per ray O(visited), not O(thicknesses).
                'specular: {
                    let cpl = self.couple(rd);
                    if cpl <= 0.0 {
                        break 'specular;
                    }
                    let back = v.z / -rd.z;
                    let w = (DVec2::new(v.x, v.y) + DVec2::new(rd.x, rd.y) * back) / den;
                    let base = ray.p0 + w * a;
                    let (mut d_lo, mut d_hi) = (-a, f64::INFINITY); // h0 = d + a > 0
                    for (p0, w0, lo, hi) in [(base.x, w.x, 0.0, x_hi), (base.y, w.y, -y_hi, y_hi)] {
                        if w0.abs() < 1e-12 {
                            if p0 < lo || p0 > hi {
                                d_hi = f64::NEG_INFINITY;
                            }
                        } else {
                            let (u, t) = ((lo - p0) / w0, (hi - p0) / w0);
                            d_lo = d_lo.max(u.min(t));
                            d_hi = d_hi.min(u.max(t));
                        }
                    }
                    if d_hi.is_nan() || d_lo.is_nan() || d_hi < d_lo {
                        break 'specular;
                    }
                    // One index of margin each side; the exact test is the bundle slot below.
                    let i_lo = ((d_lo * inv_step).max(0.0).min(nt as f64) as usize)
                        .saturating_sub(1)
                        .max(first_wet);
                    let i_hi = ((d_hi * inv_step).max(0.0).min(nt as f64) as usize + 2).min(nt);
                    if i_lo >= i_hi {
                        break 'specular;
                    }
                    // Up and back: path (d + a)·k_path, absorbed by the same ratio every step.
                    let k_path = (1.0 + back) / den;
                    let att = (-alpha * k_path * (self.thick[i_lo] + a)).exp();
                    let att_step = (-alpha * k_path * cfg.step_mm).exp();
                    let n_bub = frozen_before(&frozen_by[first_wet..i_lo]);
                    spec_slot.resize(i_hi - i_lo, 2);
                    specular_slots(
                        ray.p0,
                        w,
                        a,
                        &bundles,
                        &self.thick[i_lo..i_hi],
                        &mut spec_slot,
                    );
                    add_specular(
                        &mut refl[i_lo..i_hi],
                        &frozen_by[i_lo..i_hi],
                        &spec_slot,
                        &fwd_after,
                        n_bub,
                        [rfl, cpl],
                        [att, att_step],
                    );
                }
            }
            if had_bubbles {
                frozen_by[first_wet..].fill(0);
            }
        }
        // Flux to current.
        let ua = RESPONSIVITY_A_PER_W * 1e6;
        let mut points = Vec::with_capacity(nt);
        let mut scat = [0.0f64; 2];
        for i in 0..nt {
            scat[0] += scat_delta[i][0];
            scat[1] += scat_delta[i][1];
            let i1_refl = (refl[i][0] + SENSOR_A_LEAK[0] * leak[i]) * ua;
            let i2_refl = (refl[i][1] + SENSOR_A_LEAK[1] * leak[i]) * ua;
            let i1_scat = scat[0] * ua;
            let i2_scat = scat[1] * ua;
            points.push(CurvePoint {
                thickness_mm: self.thick[i],
                i1_ua: i1_refl + i1_scat,
                i2_ua: i2_refl + i2_scat,
                i1_refl_ua: i1_refl,
                i1_scat_ua: i1_scat,
                i2_refl_ua: i2_refl,
                i2_scat_ua: i2_scat,
            });
        }
        Curve { points }
    }
}

/// How many bubbles are frozen in up to the end of a range of thickness indices, from the
/// `frozen_by` entries of the range (0 where none is frozen in): their maximum.
fn frozen_before(frozen_by: &[u32]) -> usize {
    frozen_by.iter().copied().max().unwrap_or(0) as usize
}

/// The specular reflection of one ray at the visited thicknesses: at each, the forward flux
/// left after the bubbles frozen in so far (`fwd_after[n]`, n the running maximum of
/// `frozen_by` from `n_bub` on) times
/// the Fresnel reflectance and coupling `[rfl, cpl]` times the absorption, which falls by
/// `att[1]` per step from `att[0]`, added to the bundle of `slot`.
// Its own function: inside the tracer the running values would live on the stack.
#[inline(never)]
fn add_specular(
    refl: &mut [[f64; 2]],
    frozen_by: &[u32],
    slot: &[i32],
    fwd_after: &[f64],
    mut n_bub: usize,
    [rfl, cpl]: [f64; 2],
    [mut att, att_step]: [f64; 2],
) {
    for ((flux, &frozen), &k) in refl.iter_mut().zip(frozen_by).zip(slot) {
        let att_i = att;
        att *= att_step;
        n_bub = n_bub.max(frozen as usize);
        // Along the line the bundle changes rarely: a branch predicts well.
        let k = k as u32 as usize;
        if k < 2 {
            flux[k] += fwd_after[n_bub] * rfl * cpl * att_i;
        }
    }
}

/// Reflection of `v` at a surface with upward normal `nrm`: (Fresnel reflectance, reflected
/// direction), `None` if the ray does not meet the surface from below or does not return
/// toward the face.
#[inline]
fn reflect_setup(v: DVec3, nrm: DVec3, n_med: f64) -> Option<(f64, DVec3)> {
    let cos_i = v.dot(nrm);
    if cos_i <= 0.0 {
        return None;
    }
    let rd = crate::laws::reflect(v, nrm);
    if rd.z >= -1e-9 {
        return None;
    }
    Some((fr_dielectric(cos_i, n_med, N_AIR), rd))
}

/// One physical accretion of `cfg`, deterministic in (seed, run).
///
/// # Panics
/// If `cfg.validate()` fails.
pub fn accretion_curve(cfg: &SimConfig, seed: u64, run: u64) -> Curve {
    SensorModel::new(cfg).accretion(seed, run)
}
