//! What each source ray needs against one accretion's surface before its bubbles and its
//! reflection are traced, computed for all rays at once at the start of the accretion
//! (thesis §5.3): where the surface plane lies above the ray, how many bubble layers the ice
//! covers along it, and its specular reflection's set-up (Fresnel reflectance, coupling,
//! landing line, visited thicknesses, absorption).
//!
//! Ray by ray this set-up was a chain of a dozen divisions, two square roots and two `exp`
//! that the next ray's work could not overlap; here each step runs over all rays in vector
//! loops (the rays in lanes), with the same IEEE-754 operations per ray as the tracer had, so
//! the results are bit-identical on every tier (`setup_matches_the_ray_by_ray_formulas`).

use glam::{DVec2, DVec3};

use crate::bubbles::BubbleRay;
use crate::consts::{ALPHA_PER_MM, N_AIR, N_FIBRE};
use crate::kernels::{LANES, exp_small, grow, small_int, vector_kernel};
use crate::laws::{fr_dielectric, fresnel_transmittance, reflect};

/// Most bubble layers one ray walks through (20 000 × 0.1 mm = 2 m of ice along z).
pub(crate) const MAX_LAYERS_PER_RAY: u32 = 20_000;

/// The source rays as a structure of arrays, padded to whole vectors with copies of the
/// last ray (the padding lanes' results are never read).
#[derive(Clone, Debug, Default)]
pub(crate) struct RayLanes {
    pub p0_x: Vec<f64>,
    pub p0_y: Vec<f64>,
    pub dir_x: Vec<f64>,
    pub dir_y: Vec<f64>,
    pub dir_z: Vec<f64>,
}

impl RayLanes {
    pub(crate) fn new(rays: impl ExactSizeIterator<Item = (DVec2, DVec3)> + Clone) -> Self {
        let n = rays.len();
        let lanes = n.next_multiple_of(LANES);
        let mut out = RayLanes::default();
        let last = rays.clone().last().unwrap_or((DVec2::ZERO, DVec3::Z));
        for (p0, d) in rays.chain(std::iter::repeat_n(last, lanes - n)) {
            out.p0_x.push(p0.x);
            out.p0_y.push(p0.y);
            out.dir_x.push(d.x);
            out.dir_y.push(d.y);
            out.dir_z.push(d.z);
        }
        out
    }

    pub(crate) fn len(&self) -> usize {
        self.p0_x.len()
    }
}

/// One accretion's surface as the set-up sees it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Surface {
    /// tan δ_S,x, tan δ_S,y of the surface plane and its upward unit normal.
    pub tx: f64,
    pub ty: f64,
    pub normal: DVec3,
    /// The sensor centre's x, mm (the plane passes above it).
    pub centre_x_mm: f64,
    /// Refractive index of the medium.
    pub n_medium: f64,
    pub step_mm: f64,
    pub inv_step: f64,
    /// The first thickness index with ice and the number of thicknesses.
    pub first_wet: usize,
    pub nt: usize,
    /// The face's bounding box: 0 ≤ x ≤ x_hi, |y| ≤ y_hi (the specular pass).
    pub x_hi: f64,
    pub y_hi: f64,
}

/// Per ray (index = the ray's), for one accretion.
#[derive(Clone, Debug, Default)]
pub(crate) struct RaySetups {
    /// Height of the surface plane above the ray's fibre at d = 0, mm.
    pub a: Vec<f64>,
    /// v_z − tan δ_x v_x − tan δ_y v_y (> 0: the ray is steeper than the plane).
    pub den: Vec<f64>,
    /// The ray's sideways travel per height, (v_x, v_y)/v_z, and the plane's rise per
    /// height along it.
    pub slope_x: Vec<f64>,
    pub slope_y: Vec<f64>,
    pub off1: Vec<f64>,
    /// The bubble layers the ice covers within the thicknesses (`layers_covered`), or −1
    /// where the vector search did not settle (the tracer then searches ray by ray).
    pub layers: Vec<f64>,
    /// 1 where the ray's specular reflection returns toward the face and can land on it at
    /// some visited thickness, else 0; the fields below are meaningful where it is 1.
    pub spec_ok: Vec<f64>,
    /// The reflected direction, its Fresnel reflectance at the surface and the
    /// transmittance into a signal fibre (eqs. 3.24–3.25, before any acceptance cone).
    pub rd_x: Vec<f64>,
    pub rd_y: Vec<f64>,
    pub rd_z: Vec<f64>,
    pub rfl: Vec<f64>,
    pub fibre_t: Vec<f64>,
    /// The landing line's slope: land(d) = p0 + w·(d + a).
    pub w_x: Vec<f64>,
    pub w_y: Vec<f64>,
    /// The visited thickness indices, i_lo ≤ i < i_hi.
    pub i_lo: Vec<i32>,
    pub i_hi: Vec<i32>,
    /// The absorption up and back at i_lo, e^x₀, and its ratio per step and per eight
    /// steps, e^x₁ and e^(8·x₁) (Beer–Lambert, eq. 3.21: the absorption at i_lo + k is
    /// e^(x₀ + k·x₁)); by the polynomial `exp_small`.
    pub att: Vec<f64>,
    pub att_step: Vec<f64>,
    pub att_step8: Vec<f64>,
}

impl RaySetups {
    /// The set-up of every ray of `rays` against `surf`; `bubbles`: whether the ice has
    /// bubbles (else no layers are counted), `specular`: whether the surface reflects
    /// specularly (else no specular set-up).
    pub(crate) fn compute(
        &mut self,
        rays: &RayLanes,
        surf: &Surface,
        bubbles: bool,
        specular: bool,
    ) {
        let n = rays.len();
        for v in [
            &mut self.a,
            &mut self.den,
            &mut self.slope_x,
            &mut self.slope_y,
            &mut self.off1,
            &mut self.layers,
        ] {
            grow(v, n, 0.0);
        }
        plane_setup(
            surf,
            rays,
            &mut self.a[..n],
            &mut self.den[..n],
            &mut self.slope_x[..n],
            &mut self.slope_y[..n],
            &mut self.off1[..n],
        );
        if bubbles {
            layers_covered_lanes(
                surf,
                rays,
                &self.a[..n],
                &self.slope_x[..n],
                &self.slope_y[..n],
                &self.off1[..n],
                &mut self.layers[..n],
            );
        } else {
            self.layers[..n].fill(0.0);
        }
        if !specular {
            return;
        }
        for v in [
            &mut self.spec_ok,
            &mut self.rd_x,
            &mut self.rd_y,
            &mut self.rd_z,
            &mut self.rfl,
            &mut self.fibre_t,
            &mut self.w_x,
            &mut self.w_y,
            &mut self.att,
            &mut self.att_step,
            &mut self.att_step8,
        ] {
            grow(v, n, 0.0);
        }
        grow(&mut self.i_lo, n, 0);
        grow(&mut self.i_hi, n, 0);
        specular_setup(
            surf,
            rays,
            &self.a[..n],
            &self.den[..n],
            &mut self.spec_ok[..n],
            &mut self.rd_x[..n],
            &mut self.rd_y[..n],
            &mut self.rd_z[..n],
            &mut self.rfl[..n],
            &mut self.fibre_t[..n],
            &mut self.w_x[..n],
            &mut self.w_y[..n],
            &mut self.i_lo[..n],
            &mut self.i_hi[..n],
            &mut self.att[..n],
            &mut self.att_step[..n],
            &mut self.att_step8[..n],
        );
    }
}

vector_kernel! {
/// Where the surface plane lies above each ray: a, den, the ray's slope and the plane's rise
/// along it.
#[allow(clippy::too_many_arguments)]
fn plane_setup(
    surf: &Surface,
    rays: &RayLanes,
    a: &mut [f64],
    den: &mut [f64],
    slope_x: &mut [f64],
    slope_y: &mut [f64],
    off1: &mut [f64],
) {
    let n = a.len();
    let (p0_x, p0_y) = (&rays.p0_x[..n], &rays.p0_y[..n]);
    let (dir_x, dir_y, dir_z) = (&rays.dir_x[..n], &rays.dir_y[..n], &rays.dir_z[..n]);
    let (den, slope_x, slope_y, off1) = (&mut den[..n], &mut slope_x[..n], &mut slope_y[..n], &mut off1[..n]);
    let (tx, ty, cx) = (surf.tx, surf.ty, surf.centre_x_mm);
    for k in 0..n {
        a[k] = tx * (p0_x[k] - cx) + ty * p0_y[k];
        den[k] = dir_z[k] - tx * dir_x[k] - ty * dir_y[k];
        let slope = DVec2::new(dir_x[k], dir_y[k]) / dir_z[k];
        slope_x[k] = slope.x;
        slope_y[k] = slope.y;
        off1[k] = tx * slope.x + ty * slope.y;
    }
}
}

vector_kernel! {
/// The bubble layers the ice covers along each ray, j_end (`tracer::layers_covered`): the
/// straight-line estimate, then the same steps down and up as the search ray by ray, two
/// each; −1 where that did not settle.
#[allow(clippy::too_many_arguments)]
fn layers_covered_lanes(
    surf: &Surface,
    rays: &RayLanes,
    a: &[f64],
    slope_x: &[f64],
    slope_y: &[f64],
    off1: &[f64],
    layers: &mut [f64],
) {
    let n = layers.len();
    let (p0_x, p0_y, a) = (&rays.p0_x[..n], &rays.p0_y[..n], &a[..n]);
    let (slope_x, slope_y, off1) = (&slope_x[..n], &slope_y[..n], &off1[..n]);
    if surf.first_wet >= surf.nt {
        layers.fill(0.0);
        return;
    }
    let last = (surf.nt - 1) as f64;
    let max = f64::from(MAX_LAYERS_PER_RAY);
    for k in 0..n {
        let ray = BubbleRay {
            p0: DVec2::new(p0_x[k], p0_y[k]),
            slope_xy: DVec2::new(slope_x[k], slope_y[k]),
            a: a[k],
            off1: off1[k],
            inv_step: surf.inv_step,
            first_wet: surf.first_wet as u32,
        };
        let beyond = |j: f64| ray.cover_steps(j) > last;
        let (q0, q1) = (ray.cover_steps(0.0), ray.cover_steps(1.0));
        let slope = q1 - q0;
        let guess = f64::from(small_int(((last - q0) / slope).clamp(0.0, max)));
        let mut j = if slope > 0.0 { guess } else { 0.0 };
        for _ in 0..2 {
            j = if (j > 0.0) & beyond(j - 1.0) { j - 1.0 } else { j };
        }
        for _ in 0..2 {
            j = if (j < max) & !beyond(j) { j + 1.0 } else { j };
        }
        let settled = ((j == 0.0) | !beyond(j - 1.0)) & ((j == max) | beyond(j));
        layers[k] = if settled { j } else { -1.0 };
    }
}
}

vector_kernel! {
/// The specular reflection's set-up of each ray (`tracer::Accretion::surface_specular`):
/// reflected direction and Fresnel reflectance, transmittance into a fibre, the landing
/// line, the thicknesses whose landing point lies in the face's bounding box (one index of
/// margin each side) and the exponents of the absorption at the first of them and per step.
#[allow(clippy::too_many_arguments)]
fn specular_setup(
    surf: &Surface,
    rays: &RayLanes,
    a: &[f64],
    den: &[f64],
    ok: &mut [f64],
    rd_x: &mut [f64],
    rd_y: &mut [f64],
    rd_z: &mut [f64],
    rfl: &mut [f64],
    fibre_t: &mut [f64],
    w_x: &mut [f64],
    w_y: &mut [f64],
    i_lo: &mut [i32],
    i_hi: &mut [i32],
    att: &mut [f64],
    att_step: &mut [f64],
    att_step8: &mut [f64],
) {
    let n = ok.len();
    let (p0_x, p0_y, a, den) = (&rays.p0_x[..n], &rays.p0_y[..n], &a[..n], &den[..n]);
    let (dir_x, dir_y, dir_z) = (&rays.dir_x[..n], &rays.dir_y[..n], &rays.dir_z[..n]);
    let (rd_x, rd_y, rd_z) = (&mut rd_x[..n], &mut rd_y[..n], &mut rd_z[..n]);
    let (rfl, fibre_t, w_x, w_y) = (&mut rfl[..n], &mut fibre_t[..n], &mut w_x[..n], &mut w_y[..n]);
    let (i_lo, i_hi) = (&mut i_lo[..n], &mut i_hi[..n]);
    let (att, att_step, att_step8) = (&mut att[..n], &mut att_step[..n], &mut att_step8[..n]);
    let nt = surf.nt as f64;
    let first_wet = surf.first_wet as i32;
    for k in 0..n {
        let v = DVec3::new(dir_x[k], dir_y[k], dir_z[k]);
        let (a_k, den_k) = (a[k], den[k]);
        // Reflection (eq. 3.2) and Fresnel (eqs. 3.8–3.12); the ray must meet the surface
        // from below and return toward the face.
        let cos_i = v.dot(surf.normal);
        let rd = reflect(v, surf.normal);
        // Negated as the tracer's early returns were: a NaN does not stop the ray here either.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let returns = !(cos_i <= 0.0) & !(rd.z >= -1e-9);
        rd_x[k] = rd.x;
        rd_y[k] = rd.y;
        rd_z[k] = rd.z;
        rfl[k] = fr_dielectric(cos_i, surf.n_medium, N_AIR);
        fibre_t[k] = fresnel_transmittance(-rd.z, surf.n_medium, N_FIBRE);
        // The landing line and the thicknesses at which it can lie on the face's box.
        let back = v.z / -rd.z;
        let w = (DVec2::new(v.x, v.y) + DVec2::new(rd.x, rd.y) * back) / den_k;
        w_x[k] = w.x;
        w_y[k] = w.y;
        let base = DVec2::new(p0_x[k], p0_y[k]) + w * a_k;
        let (mut d_lo, mut d_hi) = (-a_k, f64::INFINITY); // h0 = d + a > 0
        for (p0, w0, lo, hi) in [
            (base.x, w.x, 0.0, surf.x_hi),
            (base.y, w.y, -surf.y_hi, surf.y_hi),
        ] {
            let (u, t) = ((lo - p0) / w0, (hi - p0) / w0);
            let parallel = w0.abs() < 1e-12;
            let outside = (p0 < lo) | (p0 > hi);
            d_lo = if parallel { d_lo } else { d_lo.max(u.min(t)) };
            d_hi = if parallel {
                if outside { f64::NEG_INFINITY } else { d_hi }
            } else {
                d_hi.min(u.max(t))
            };
        }
        let on_box = !(d_hi.is_nan() | d_lo.is_nan() | (d_hi < d_lo));
        let lo_k = (small_int((d_lo * surf.inv_step).max(0.0).min(nt)) - 1).max(0).max(first_wet);
        let hi_k = (small_int((d_hi * surf.inv_step).max(0.0).min(nt)) + 2).min(surf.nt as i32);
        i_lo[k] = lo_k;
        i_hi[k] = hi_k;
        ok[k] = if returns & on_box & (lo_k < hi_k) { 1.0 } else { 0.0 };
        // Up and back: path (d + a)·k_path, absorbed by the same ratio every step.
        let k_path = (1.0 + back) / den_k;
        let x1 = -ALPHA_PER_MM * k_path * surf.step_mm;
        att[k] = exp_small(-ALPHA_PER_MM * k_path * (f64::from(lo_k) * surf.step_mm + a_k));
        att_step[k] = exp_small(x1);
        att_step8[k] = exp_small(LANES as f64 * x1);
    }
}
}

#[cfg(test)]
mod tests;
