//! One accretion traced ray by ray (thesis §3.2, §5.3), in phases:
//!
//! 1. [`Accretion::new`]: the accretion's surface (slopes δ_S,x, δ_S,y from stream 0), the
//!    sums per thickness, and every ray's set-up against the surface, all rays at once
//!    (setup.rs: where the plane lies above the ray, the bubble layers the ice covers, the
//!    specular reflection's Fresnel factors, landing line, visited thicknesses, absorption);
//! 2. per ray, [`Accretion::trace`]: its frame against the surface ([`RayFrame`]), then
//!    pass 1, the bubbles ([`Accretion::bubbles_dense`] for rime, [`Accretion::bubbles_sparse`]
//!    for glazed), which leaves the forward flux after each bubble and where it is frozen in,
//!    then pass 2, the surface at every thickness ([`Accretion::surface_diffuse`] or
//!    [`Accretion::surface_specular`], and Sensor A's leak);
//! 3. [`Accretion::into_curve`]: flux to current, the scattered light prefix-summed.
//!
//! Cost O(rays × (thicknesses + bubbles)); sim/README, *Speed*.

use glam::{DVec2, DVec3};
use rand_pcg::Pcg32;

use crate::bubbles::{BubbleLanes, BubbleRay, land_scattered};
use crate::config::{Coupling, DiffuseFresnel, SensorKind};
use crate::consts::*;
use crate::curve::{Curve, CurvePoint};
use crate::diffuse::{DiffuseLanes, DiffuseRay, reflect_diffuse};
use crate::geometry::Bundles;
use crate::kernels::{LANES, grow};
use crate::model::{SensorModel, SourceRay};
use crate::setup::{MAX_LAYERS_PER_RAY, RaySetups, Surface};
use crate::specular::{SpecularFlux, SpecularLine, SpecularRay, specular_reflection};
use crate::streams::{
    CounterStream, STREAM_ACCRETION, accretion_key, bubble_stream, diffuse_stream, fill_u32,
    geometric_gap, uniform, uniform32, unit_circle_unnormalised,
};
use crate::walk::{GROUP_RAYS, GapSampler};

/// One accretion being traced: its surface, the sums per thickness and the scratch buffers
/// the rays share.
pub(crate) struct Accretion<'m> {
    m: &'m SensorModel,
    key: u64,
    /// tan δ_S,x, tan δ_S,y of the surface plane, and its upward unit normal.
    tx: f64,
    ty: f64,
    normal: DVec3,
    nt: usize,
    /// The first thickness index with ice (thickness 0 is the dry face).
    first_wet: usize,
    inv_step: f64,
    ln_q: f64,
    bundles: Bundles,
    /// The face's bounding box: x_lo ≤ x ≤ x_hi, |y| ≤ y_hi (culling of scattered rays).
    x_lo: f64,
    x_hi: f64,
    y_hi: f64,
    /// The circle around the bundles (0 ≤ x ≤ B + R, |y| ≤ R): a reflection that lands
    /// farther than `face_radius` from `face_centre` misses them.
    face_centre: DVec2,
    face_radius: f64,
    /// Dense bubbles: the forward flux after n bubbles is Φ·F^n, read as `fwd_scale` ×
    /// `forward_pow[n]` (the same product, so the same bits) instead of from `fwd_after`.
    fwd_dense: bool,
    fwd_scale: f64,
    /// The sums and every buffer the rays share, reused from one accretion to the next
    /// on a thread ([`Scratch`]).
    buf: Scratch,
    /// The first ray of the group whose dense bubbles `lanes` holds (walked side by side).
    group_first: Option<usize>,
}

/// The sums of one accretion and the buffers its rays share: kept by each thread from one
/// accretion to the next ([`Scratch::with`]), so that an accretion allocates nothing. The
/// sums are zeroed for each accretion; the other buffers only grow, and a ray reads only
/// what it wrote.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    /// Reflected flux per bundle and thickness, W (each padded by a vector of lanes, which
    /// the specular sums may add +0 to).
    refl: [Vec<f64>; 2],
    /// Scattered flux newly frozen in at each thickness, per bundle, W.
    scat_delta: Vec<[f64; 2]>,
    /// Flux reflected at the fibre face per thickness (Sensor A), W.
    leak: Vec<f64>,
    /// Per ray: the forward flux after n bubbles (`fwd_after[n]`) and, at each thickness index
    /// where bubbles are frozen in, how many are frozen in up to it (`frozen_by`, 0 at the
    /// other indices: the bubbles are frozen in in walk order, so the number frozen in at
    /// indices ≤ i is the running maximum). The forward flux at thickness i is
    /// fwd_after[that number].
    fwd_after: Vec<f64>,
    frozen_by: Vec<u32>,
    /// F^n, n = 0, 1, …: grown to the most bubbles one ray met.
    forward_pow: Vec<f64>,
    lanes: BubbleLanes,
    landed: Vec<u32>,
    /// Per visited thickness of a ray: the bubbles frozen in up to it, and its bundle (the
    /// specular pass's scratch on the tiers below AVX-512).
    spec_count: Vec<u32>,
    spec_bundle: Vec<i32>,
    diffuse_draws: Vec<u32>,
    diffuse_out: DiffuseLanes,
    diffuse_bubbles: Vec<usize>,
    /// Every ray's set-up against this surface (setup.rs).
    setup: RaySetups,
}

impl Scratch {
    /// Run `f` with this thread's scratch, sized and zeroed for `nt` thicknesses.
    pub(crate) fn with<R>(nt: usize, f: impl FnOnce(Scratch) -> (R, Scratch)) -> R {
        thread_local! {
            static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
        }
        let mut s = SCRATCH.with(|c| c.take());
        for sums in &mut s.refl {
            sums.clear();
            sums.resize(nt + LANES, 0.0);
        }
        s.scat_delta.clear();
        s.scat_delta.resize(nt, [0.0; 2]);
        s.leak.clear();
        s.leak.resize(nt, 0.0);
        // Padded by a vector of lanes that stay 0 (the specular sums read them).
        s.frozen_by.clear();
        s.frozen_by.resize(nt + LANES, 0);
        if s.forward_pow.is_empty() {
            s.forward_pow.push(1.0);
        }
        let (out, s) = f(s);
        SCRATCH.with(|c| c.replace(s));
        out
    }
}

/// One ray against this accretion's surface.
struct RayFrame {
    /// The ray's index (its streams) and the ray.
    r: usize,
    ray: SourceRay,
    /// Height of the surface plane above the ray's fibre at d = 0, mm.
    a: f64,
    /// v_z − tan δ_x v_x − tan δ_y v_y (> 0: the ray is steeper than the plane).
    den: f64,
    /// The ray's bubble geometry.
    bubble: BubbleRay,
}

impl SensorModel {
    /// Trace one accretion: one physical ice body grown from 0 to `max_mm`, deterministic
    /// in (seed, run). Cost O(rays × (thicknesses + bubbles)); the phases in `tracer.rs`.
    pub fn accretion(&self, seed: u64, run: u64) -> Curve {
        Scratch::with(self.thick.len(), |buf| {
            let mut acc = Accretion::new(self, seed, run, buf);
            for (r, ray) in self.rays.iter().enumerate() {
                acc.trace(r, ray);
            }
            acc.into_curve()
        })
    }
}

impl<'m> Accretion<'m> {
    /// Phase 1: the surface of accretion `run` of `seed`, and empty sums.
    pub(crate) fn new(m: &'m SensorModel, seed: u64, run: u64, buf: Scratch) -> Self {
        let cfg = &m.cfg;
        let p = cfg.params;
        let geo = cfg.geometry;
        let key = accretion_key(seed, run);
        let mut acc = Pcg32::new(key, STREAM_ACCRETION);
        let sx = p.slope_max_rad * (2.0 * uniform(&mut acc) - 1.0);
        let sy = p.slope_max_rad * (2.0 * uniform(&mut acc) - 1.0);
        let (tx, ty) = (sx.tan(), sy.tan());
        let nt = m.thick.len();
        let (x_lo, x_hi, y_hi) = (
            -geo.radius_mm(),
            geo.length_b_mm() + geo.radius_mm(),
            geo.radius_mm(),
        );
        let face_centre = DVec2::new(0.5 * x_hi, 0.0);
        Accretion {
            m,
            key,
            tx,
            ty,
            normal: DVec3::new(-tx, -ty, 1.0).normalize(),
            nt,
            first_wet: m.thick.iter().position(|&d| d > 0.0).unwrap_or(nt),
            inv_step: 1.0 / cfg.step_mm,
            ln_q: if p.p_bubble > 0.0 {
                (1.0 - p.p_bubble).ln()
            } else {
                0.0
            },
            bundles: geo.bundles(),
            x_lo,
            x_hi,
            y_hi,
            face_centre,
            face_radius: face_centre.x.hypot(y_hi),
            fwd_dense: false,
            fwd_scale: 1.0,
            buf,
            group_first: None,
        }
        .with_setup()
    }

    /// Phase 1 continued: every ray's set-up against the surface (setup.rs).
    fn with_setup(mut self) -> Self {
        let m = self.m;
        let geo = m.cfg.geometry;
        let surf = Surface {
            tx: self.tx,
            ty: self.ty,
            normal: self.normal,
            centre_x_mm: geo.centre_x_mm(),
            n_medium: m.cfg.params.n_medium,
            step_mm: m.cfg.step_mm,
            inv_step: self.inv_step,
            first_wet: self.first_wet,
            nt: self.nt,
            x_hi: self.x_hi,
            y_hi: self.y_hi,
        };
        let bubbles = m.cfg.params.p_bubble > 0.0;
        let specular = m.cfg.params.diffuse_max_rad <= 0.0; // validated: not NaN
        self.buf
            .setup
            .compute(&m.ray_lanes, &surf, bubbles, specular);
        self
    }

    /// Phase 2, one ray: its bubbles, then the surface at every thickness.
    pub(crate) fn trace(&mut self, r: usize, ray: &SourceRay) {
        let m = self.m;
        let p = m.cfg.params;
        let sensor_a = m.cfg.sensor == SensorKind::A;
        if sensor_a {
            for l in self.buf.leak.iter_mut().take(self.first_wet) {
                *l += ray.refl_air_w;
            }
        }
        if !self.traced(r, ray) {
            return;
        }
        let su = &self.buf.setup;
        let (a, den, layers) = (su.a[r], su.den[r], su.layers[r]);
        // Pass 1, bubbles: layer j (z from jΔ to (j+1)Δ, bubble at its middle) is frozen in
        // once the local surface above the bubble is at least (j+1)Δ high, i.e. from the mean
        // thickness d_j = (j+1)Δ − off(z_b), where off is the plane's local offset at the
        // bubble. d_j grows with j (the ray is steeper than the plane: den > 0), so the
        // forward flux at each thickness is a running product, stored as fwd_after[n] and,
        // per index, the number of bubbles frozen in up to it.
        let f = RayFrame {
            r,
            ray: *ray,
            a,
            den,
            bubble: self.bubble_ray(r, ray),
        };
        let had_bubbles = match &m.dense {
            Some(gaps) => self.bubbles_dense(&f, gaps) > 0,
            None => {
                self.buf.fwd_after.clear();
                self.buf.fwd_after.push(ray.flux_in_w);
                self.bubbles_sparse(&f, self.layers_of(&f.bubble, layers));
                self.buf.fwd_after.len() > 1
            }
        };

        // Pass 2, the surface at every thickness.
        if sensor_a {
            for (i, l) in self.buf.leak.iter_mut().enumerate().skip(self.first_wet) {
                *l += if m.thick[i] + a <= 0.0 {
                    ray.refl_air_w
                } else {
                    ray.refl_med_w
                };
            }
        }
        if p.diffuse_max_rad > 0.0 {
            self.surface_diffuse(&f, had_bubbles);
        } else {
            self.surface_specular(&f);
        }
        if had_bubbles {
            let first_wet = self.first_wet;
            self.buf.frozen_by[first_wet..].fill(0);
        }
    }

    /// The layers j < j_end that the ice covers within max_mm along a ray (`bubble`), from
    /// its set-up's `layers` (negative where the set-up's search did not settle). A ray
    /// almost parallel to a tilted surface would walk very many layers before the surface
    /// covers them: at most MAX_LAYERS_PER_RAY (2 m). Beyond, the bubbles are not drawn.
    fn layers_of(&self, bubble: &BubbleRay, layers: f64) -> u32 {
        if self.m.cfg.params.p_bubble <= 0.0 {
            0
        } else if layers >= 0.0 {
            layers as u32
        } else {
            layers_covered(
                &|j: u32| bubble.cover_steps(f64::from(j)),
                self.first_wet,
                self.nt,
            )
        }
    }

    /// Whether ray r (`ray`) is traced: it carries flux and is steeper than the surface
    /// plane. Written as a negation, so that a NaN does not stop the ray.
    fn traced(&self, r: usize, ray: &SourceRay) -> bool {
        !(ray.flux_in_w <= 0.0 || self.buf.setup.den[r] <= 1e-9)
    }

    /// Ray r (`ray`) as the bubbles see it, from its set-up.
    fn bubble_ray(&self, r: usize, ray: &SourceRay) -> BubbleRay {
        let su = &self.buf.setup;
        BubbleRay {
            p0: ray.p0,
            slope_xy: DVec2::new(su.slope_x[r], su.slope_y[r]),
            a: su.a[r],
            off1: su.off1[r],
            inv_step: self.inv_step,
            first_wet: self.first_wet as u32,
        }
    }

    /// Walk the dense bubbles of the group of rays from `first` on, side by side
    /// (walk.rs); a ray that is not traced walks no layer.
    fn walk_group(&mut self, first: usize, gaps: &GapSampler) {
        let rays = &self.m.rays;
        let j_end = std::array::from_fn(|l| {
            let r = first + l;
            match rays.get(r) {
                Some(ray) if self.traced(r, ray) => {
                    self.layers_of(&self.bubble_ray(r, ray), self.buf.setup.layers[r])
                }
                _ => 0,
            }
        });
        let streams =
            std::array::from_fn(|l| CounterStream::new(self.key, bubble_stream(first + l)));
        self.buf.lanes.walk_group(streams, gaps, j_end);
        self.group_first = Some(first);
    }

    /// The scattered part of a bubble: 5 % deflected toward the face (Fig. 3.11), attenuated
    /// along the ray up to the bubble and down to the face (Beer–Lambert, eq. 3.21), entering
    /// bundle `k` with the coupling of eqs. 3.24–3.25, frozen in at thickness index `i`.
    #[inline]
    fn scatter(
        &mut self,
        f: &RayFrame,
        (i, k): (usize, usize),
        fwd: f64,
        s: DVec3,
        z_b: f64,
        reach: f64,
    ) {
        let path = z_b / f.ray.dir.z + reach;
        self.buf.scat_delta[i][k] +=
            fwd * (1.0 - FORWARD_FRACTION) * self.m.couple(s) * (-ALPHA_PER_MM * path).exp();
    }

    /// Pass 1, dense bubbles (rime): the walk draws one geometric gap per bubble from a
    /// counter-based stream, then lands all scattered rays at once (bubbles.rs).
    fn bubbles_dense(&mut self, f: &RayFrame, gaps: &GapSampler) -> usize {
        let (lane, first) = (f.r % GROUP_RAYS, f.r - f.r % GROUP_RAYS);
        if self.group_first != Some(first) {
            self.walk_group(first, gaps);
        }
        self.buf.lanes.select(lane);
        land_scattered(&f.bubble, &self.bundles, &mut self.buf.lanes);
        let count = self.buf.lanes.len();
        // Forward flux after n bubbles: Φ·F^n (F = FORWARD_FRACTION).
        grow_forward_pow(&mut self.buf.forward_pow, count);
        (self.fwd_dense, self.fwd_scale) = (true, f.ray.flux_in_w);
        let landed_count = self
            .buf
            .lanes
            .tally(&mut self.buf.frozen_by, &mut self.buf.landed);
        // The thesis's coupling needs only cos θ_B; the acceptance cone the whole direction.
        let sideways = self.m.cfg.coupling == Coupling::AcceptanceCone;
        for l in 0..landed_count {
            let n = self.buf.landed[l] as usize;
            let sc = self.buf.lanes.scattered(n, sideways);
            let at = (
                self.buf.lanes.index[n] as usize,
                self.buf.lanes.slot[n] as usize,
            );
            let fwd = self.fwd_scale * self.buf.forward_pow[n];
            self.scatter(f, at, fwd, DVec3::from(sc.dir), sc.z_mm, sc.reach_mm);
        }
        count
    }

    /// Pass 1, sparse bubbles (glazed): geometric gaps between bubbles by inversion (one `ln`
    /// per bubble), P_B per layer; each bubble's scattered ray is culled before its azimuth is
    /// drawn when it cannot reach the face.
    fn bubbles_sparse(&mut self, f: &RayFrame, j_end: u32) {
        self.fwd_dense = false;
        let ray = &f.ray;
        let slope_xy = f.bubble.slope_xy;
        let mut bub = Pcg32::new(self.key, bubble_stream(f.r));
        let mut j: u32 = if self.m.cfg.params.p_bubble > 0.0 {
            geometric_gap(&mut bub, self.ln_q)
        } else {
            j_end
        };
        let mut fwd = ray.flux_in_w;
        while j < j_end {
            let z_b = (j as f64 + 0.5) * BUBBLE_LAYER_MM;
            // First output index at or above d_j (j < j_end: below nt).
            let i = ceil_index(f.bubble.cover_steps(f64::from(j))).max(self.first_wet);
            let b = ray.p0 + slope_xy * z_b;
            let cos_b = 1.0 - uniform32(&mut bub); // isotropic over the lower hemisphere
            let sin2_b = (1.0 - cos_b * cos_b).max(0.0);
            // Horizontal travel z_b·tan θ_B; beyond the farthest point of the face the ray
            // misses whatever its azimuth, so the azimuth is not drawn.
            let far_x = (b.x - self.x_lo).abs().max((b.x - self.x_hi).abs());
            let far_y = b.y.abs() + self.y_hi;
            let travel2 = z_b * z_b * sin2_b / (cos_b * cos_b);
            if travel2 <= far_x * far_x + far_y * far_y {
                let (ua, ub, uq) = unit_circle_unnormalised(&mut bub);
                let norm = uq.sqrt().recip();
                let (c_phi, s_phi) = (ua * norm, ub * norm);
                let sin_b = sin2_b.sqrt();
                let reach = z_b / cos_b;
                let land = b + DVec2::new(c_phi, s_phi) * (sin_b * reach);
                let k = self.bundles.slot(land.x, land.y);
                if k < 2 {
                    let s = DVec3::new(sin_b * c_phi, sin_b * s_phi, -cos_b);
                    self.scatter(f, (i, k), fwd, s, z_b, reach);
                }
            }
            fwd *= FORWARD_FRACTION;
            self.buf.fwd_after.push(fwd);
            self.buf.frozen_by[i] = (self.buf.fwd_after.len() - 1) as u32;
            let gap = geometric_gap(&mut bub, self.ln_q);
            j = j.saturating_add(1).saturating_add(gap);
        }
        grow_forward_pow(&mut self.buf.forward_pow, self.buf.fwd_after.len() - 1);
    }

    /// Pass 2 with diffuse angles: the surface is above the fibre (h0 = d + a > 0) from
    /// index i0 on; one diffuse angle is drawn per such thickness, in order. The reflected
    /// rays of all of them are traced at once (kernels.rs), then added in order.
    fn surface_diffuse(&mut self, f: &RayFrame, had_bubbles: bool) {
        let m = self.m;
        let cfg = &m.cfg;
        let (ray, a, nt, first_wet) = (&f.ray, f.a, self.nt, self.first_wet);
        let i0 = first_index(first_wet, nt, -a * self.inv_step, |i| m.thick[i] + a > 0.0);
        let dray = DiffuseRay {
            v: ray.dir,
            normal: self.normal,
            p0: [ray.p0.x, ray.p0.y],
            a,
            den: f.den,
            diffuse_max_rad: cfg.params.diffuse_max_rad,
            half_max_sin_cos: m.half_diffuse_sin_cos,
            facet_fresnel: cfg.diffuse_fresnel == DiffuseFresnel::Facet,
            n_medium: cfg.params.n_medium,
            n_air: N_AIR,
            n_fibre: N_FIBRE,
            alpha_per_mm: ALPHA_PER_MM,
        };
        // Beyond a thickness that depends on the ray no diffuse angle brings the reflection
        // back onto the face: those thicknesses are not traced, nor their angles drawn (the
        // draws are the stream's first ones, in order).
        let reach = (ray.p0 - self.face_centre).length() + self.face_radius;
        let h0_max = dray.h0_cutoff_mm(reach);
        // Negated, so that a NaN bound keeps every thickness.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let i_end = first_index(i0, nt, (h0_max - a) * self.inv_step, |i| {
            !(m.thick[i] + a <= h0_max)
        });
        // The lanes padded to whole vectors: the draws go on in the stream, the thicknesses
        // on their grid; the padding lanes are not counted.
        let lanes = (i_end - i0).next_multiple_of(LANES);
        grow(&mut self.buf.diffuse_draws, lanes, 0);
        fill_u32(
            self.key,
            diffuse_stream(f.r),
            &mut self.buf.diffuse_draws[..lanes],
        );
        reflect_diffuse(
            &dray,
            &self.bundles,
            &m.thick_lanes[i0..i0 + lanes],
            i_end - i0,
            &self.buf.diffuse_draws[..lanes],
            &mut self.buf.diffuse_out,
        );
        // The bubbles frozen in up to each landed thickness: a running maximum
        // (`frozen_by`), needed only when the ray met bubbles.
        let n_bub0 = frozen_before(&self.buf.frozen_by[first_wet..i0]);
        if had_bubbles {
            // Into a buffer that only grows, by plain stores (a `Vec` push per entry stored
            // its length every time).
            grow(&mut self.buf.diffuse_bubbles, i_end - i0, 0);
            let mut b = n_bub0;
            for (o, &f) in self.buf.diffuse_bubbles[..i_end - i0]
                .iter_mut()
                .zip(&self.buf.frozen_by[i0..i_end])
            {
                b = b.max(f as usize);
                *o = b;
            }
        }
        let cone = cfg.coupling == Coupling::AcceptanceCone;
        let d = &self.buf.diffuse_out;
        let (landed, weight) = d.landed();
        let slot = &d.slot[..];
        let (scale, table) = forward_flux(
            self.fwd_dense,
            self.fwd_scale,
            &self.buf.forward_pow,
            &self.buf.fwd_after,
        );
        let [refl0, refl1] = &mut self.buf.refl;
        let refl = [&mut refl0[i0..i_end], &mut refl1[i0..i_end]];
        if !cone && !had_bubbles {
            // The common case (glazed ice: most rays meet no bubble), without a branch per
            // lane: the same forward flux for every thickness. A landed lane's slot is 0 or
            // 1, so `& 1` keeps it and spares the bounds check.
            let fwd = scale * table[n_bub0];
            for (&n, &w) in landed.iter().zip(weight) {
                let n = n as usize;
                debug_assert!(slot[n] < 2, "a landed lane has a bundle");
                refl[(slot[n] & 1) as usize][n] += fwd * w;
            }
            return;
        }
        for (&n, &w) in landed.iter().zip(weight) {
            let n = n as usize;
            if cone && !m.in_acceptance_cone(DVec3::new(d.dir[0][n], d.dir[1][n], d.dir[2][n])) {
                continue;
            }
            let fwd = if had_bubbles {
                scale * table[self.buf.diffuse_bubbles[n]]
            } else {
                scale * table[n_bub0]
            };
            debug_assert!(slot[n] < 2, "a landed lane has a bundle");
            refl[(slot[n] & 1) as usize][n] += fwd * w;
        }
    }

    /// Pass 2 without diffuse angles: specular reflection, fixed per accretion. The landing
    /// point moves on a line, land(d) = p0 + w·(d + a), so only the thicknesses whose landing
    /// point lies in the face's bounding box are visited (the bundles are convex, their union
    /// too): cost per ray O(visited), not O(thicknesses).
    fn surface_specular(&mut self, f: &RayFrame) {
        let m = self.m;
        let (ray, a, r) = (&f.ray, f.a, f.r);
        // The reflection's set-up (setup.rs): the reflected ray returns toward the face, and
        // the visited thicknesses are those whose landing point lies in the face's bounding
        // box (one index of margin each side; the exact test is the bundle slot below).
        let su = &self.buf.setup;
        if su.spec_ok[r] == 0.0 {
            return;
        }
        let rd = DVec3::new(su.rd_x[r], su.rd_y[r], su.rd_z[r]);
        let cpl = m.couple_transmitted(rd, su.fibre_t[r]);
        if cpl <= 0.0 {
            return;
        }
        let (rfl, w) = (su.rfl[r], DVec2::new(su.w_x[r], su.w_y[r]));
        let (i_lo, i_hi) = (su.i_lo[r] as usize, su.i_hi[r] as usize);
        let absorption = [su.att[r], su.att_step[r], su.att_step8[r]];
        let n_before = frozen_before(&self.buf.frozen_by[self.first_wet..i_lo]);
        // Padded to whole vectors (the thicknesses go on on their grid); the padding lanes
        // are not added.
        let lanes = (i_hi - i_lo).next_multiple_of(LANES);
        grow(&mut self.buf.spec_count, lanes, 0);
        grow(&mut self.buf.spec_bundle, lanes, 2);
        let [refl0, refl1] = &mut self.buf.refl;
        let spec = SpecularRay {
            line: SpecularLine { p0: ray.p0, w, a },
            thick_mm: &m.thick_lanes[i_lo..i_lo + lanes],
            frozen_by: &self.buf.frozen_by[i_lo..i_lo + lanes],
            len: i_hi - i_lo,
            n_before: n_before as u32,
            flux: SpecularFlux {
                scale: ray.flux_in_w * rfl * cpl,
                forward_pow: &self.buf.forward_pow,
                absorption,
            },
        };
        specular_reflection(
            &spec,
            &self.bundles,
            &mut refl0[i_lo..i_lo + lanes],
            &mut refl1[i_lo..i_lo + lanes],
            &mut self.buf.spec_count[..lanes],
            &mut self.buf.spec_bundle[..lanes],
        );
    }

    /// Phase 3: flux to current; the scattered light frozen in at each thickness summed up.
    pub(crate) fn into_curve(self) -> (Curve, Scratch) {
        let ua = RESPONSIVITY_A_PER_W * 1e6;
        let mut points = Vec::with_capacity(self.nt);
        let mut scat = [0.0f64; 2];
        for (i, &d) in self.m.thick.iter().enumerate() {
            scat[0] += self.buf.scat_delta[i][0];
            scat[1] += self.buf.scat_delta[i][1];
            let i1_refl = (self.buf.refl[0][i] + SENSOR_A_LEAK[0] * self.buf.leak[i]) * ua;
            let i2_refl = (self.buf.refl[1][i] + SENSOR_A_LEAK[1] * self.buf.leak[i]) * ua;
            let i1_scat = scat[0] * ua;
            let i2_scat = scat[1] * ua;
            points.push(CurvePoint {
                thickness_mm: d,
                i1_ua: i1_refl + i1_scat,
                i2_ua: i2_refl + i2_scat,
                i1_refl_ua: i1_refl,
                i1_scat_ua: i1_scat,
                i2_refl_ua: i2_refl,
                i2_scat_ua: i2_scat,
            });
        }
        (Curve { points }, self.buf)
    }
}

/// The forward flux after n bubbles as `scale` × `table[n]`: Φ·F^n (`pow[n]` = F^n) for
/// dense bubbles, the running product `after[n]` (times 1, exactly) for sparse ones. From
/// the tracer's fields, so that another of them can be borrowed mutably beside it.
fn forward_flux<'a>(dense: bool, scale: f64, pow: &'a [f64], after: &'a [f64]) -> (f64, &'a [f64]) {
    if dense { (scale, pow) } else { (1.0, after) }
}

/// The number of bubble layers a ray meets within the output thicknesses: the first layer j
/// whose q(j) (its thickness in output steps, non-decreasing in j) lies beyond the last
/// output index, at most `MAX_LAYERS_PER_RAY`. Layer j is frozen in at the first index
/// i ≥ `first_wet` with i ≥ q(j); j_end is the first layer for which that index is ≥ `nt`.
pub(crate) fn layers_covered(q_of: &impl Fn(u32) -> f64, first_wet: usize, nt: usize) -> u32 {
    if first_wet >= nt {
        return 0;
    }
    let last = (nt - 1) as f64;
    // q is linear in j up to rounding: start from the straight-line estimate, then settle
    // on the exact first j with the same comparisons as a walk layer by layer.
    let (q0, q1) = (q_of(0), q_of(1));
    let slope = q1 - q0;
    let mut j = if slope > 0.0 {
        ((last - q0) / slope).clamp(0.0, MAX_LAYERS_PER_RAY as f64) as u32
    } else {
        0
    };
    let beyond = |j: u32| q_of(j) > last;
    while j > 0 && beyond(j - 1) {
        j -= 1;
    }
    while j < MAX_LAYERS_PER_RAY && !beyond(j) {
        j += 1;
    }
    j
}

/// The first index i in `from..to` at which `beyond(i)` holds (`to` if none), for a
/// predicate that holds from some index on: searched from the guess `near` (an index as
/// an f64, any value), so that it costs the distance from the guess, not a scan or a
/// binary search. The same answer as `(from..to).find(beyond)`.
// `layers_covered` searches the same way, written out: through this function it cost 5 %
// of rime's time (measured).
#[inline]
fn first_index(from: usize, to: usize, near: f64, beyond: impl Fn(usize) -> bool) -> usize {
    if from >= to {
        return from;
    }
    // `as` saturates and sends NaN to 0.
    let mut i = (near.max(0.0) as usize).clamp(from, to);
    while i > from && beyond(i - 1) {
        i -= 1;
    }
    while i < to && !beyond(i) {
        i += 1;
    }
    i
}

/// The smallest integer i ≥ 0 with i ≥ q, as an index (q ≤ `usize::MAX`): ceil without a
/// libm call. Exact: `i as f64 >= q` and `(i - 1) as f64 < q` for every finite q.
#[inline]
fn ceil_index(q: f64) -> usize {
    let t = q as i64; // toward zero: the ceiling for q ≤ 0, the floor for q > 0
    let t = if (t as f64) < q { t + 1 } else { t };
    t.max(0) as usize
}

/// `forward_pow` holds F^n (F = FORWARD_FRACTION, fig. 3.11) for n = 0 ..= `most`, each the
/// one before times F.
fn grow_forward_pow(forward_pow: &mut Vec<f64>, most: usize) {
    while forward_pow.len() <= most {
        let last = forward_pow.last().copied().unwrap_or(1.0);
        forward_pow.push(last * FORWARD_FRACTION);
    }
}

/// How many bubbles are frozen in up to the end of a range of thickness indices, from the
/// `frozen_by` entries of the range (0 where none is frozen in): their maximum.
fn frozen_before(frozen_by: &[u32]) -> usize {
    frozen_by.iter().copied().max().unwrap_or(0) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `first_index` answers as a scan from `from` does, whatever its guess (far off, on
    /// either side, NaN, infinite) and for predicates that never or always hold.
    #[test]
    fn first_index_finds_what_a_scan_finds_from_any_guess() {
        let guesses = [
            f64::NAN,
            f64::NEG_INFINITY,
            f64::INFINITY,
            -5.0,
            0.0,
            3.7,
            17.0,
            40.0,
            1e9,
        ];
        for (from, to) in [(0, 0), (0, 1), (3, 3), (0, 30), (5, 30), (12, 13)] {
            for edge in 0..=32 {
                let beyond = |i: usize| i >= edge;
                let want = (from..to).find(|&i| beyond(i)).unwrap_or(to);
                for near in guesses {
                    assert_eq!(
                        first_index(from, to, near, beyond),
                        want,
                        "{from}..{to}, edge {edge}, guess {near}"
                    );
                }
            }
        }
    }

    /// The layers a ray meets: the first layer beyond the last output index, by a scan.
    #[test]
    fn layers_covered_matches_a_walk_layer_by_layer() {
        for (q0, dq) in [
            (-3.0, 0.97),
            (0.4, 1.0),
            (-0.2, 0.013),
            (2.0, 0.0),
            (5.0, -1.0),
        ] {
            let q = |j: u32| q0 + dq * f64::from(j);
            for (first_wet, nt) in [(1, 151), (0, 40), (151, 151)] {
                let got = layers_covered(&q, first_wet, nt);
                let want = if first_wet >= nt {
                    0
                } else {
                    (0..MAX_LAYERS_PER_RAY)
                        .find(|&j| q(j) > (nt - 1) as f64)
                        .unwrap_or(MAX_LAYERS_PER_RAY)
                };
                assert_eq!(got, want, "q0 {q0}, dq {dq}, {first_wet}..{nt}");
            }
        }
    }
}
