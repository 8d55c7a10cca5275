//! The set-up's kernels against the tracer's ray-by-ray formulas (a file of its own: it
//! reads the model and the tracer, which read the set-up).

use super::*;
use crate::config::{IceKind, SensorKind, SimConfig};
use crate::geometry::Geometry;
use crate::kernels::{Isa, isa, with_isa};
use crate::model::SensorModel;
use crate::streams::uniform;
use crate::tracer::layers_covered;
use rand_pcg::Pcg32;

/// The specular set-up of one ray as the tracer computed it ray by ray (`None` where the
/// reflection is not traced): rd, rfl, fibre t, w, i_lo, i_hi, and the absorption's
/// exponents att, att_step.
#[allow(clippy::type_complexity)]
fn specular_by_ray(
    p0: DVec2,
    v: DVec3,
    surf: &Surface,
    a: f64,
    den: f64,
) -> Option<(DVec3, f64, f64, DVec2, usize, usize, [f64; 3])> {
    let cos_i = v.dot(surf.normal);
    if cos_i <= 0.0 {
        return None;
    }
    let rd = reflect(v, surf.normal);
    if rd.z >= -1e-9 {
        return None;
    }
    let rfl = fr_dielectric(cos_i, surf.n_medium, N_AIR);
    let t = fresnel_transmittance(-rd.z, surf.n_medium, N_FIBRE);
    let back = v.z / -rd.z;
    let w = (DVec2::new(v.x, v.y) + DVec2::new(rd.x, rd.y) * back) / den;
    let base = p0 + w * a;
    let (mut d_lo, mut d_hi) = (-a, f64::INFINITY);
    for (p, w0, lo, hi) in [
        (base.x, w.x, 0.0, surf.x_hi),
        (base.y, w.y, -surf.y_hi, surf.y_hi),
    ] {
        if w0.abs() < 1e-12 {
            if p < lo || p > hi {
                d_hi = f64::NEG_INFINITY;
            }
        } else {
            let (u, t) = ((lo - p) / w0, (hi - p) / w0);
            d_lo = d_lo.max(u.min(t));
            d_hi = d_hi.min(u.max(t));
        }
    }
    if d_hi.is_nan() || d_lo.is_nan() || d_hi < d_lo {
        return None;
    }
    let nt = surf.nt;
    let i_lo = ((d_lo * surf.inv_step).max(0.0).min(nt as f64) as usize)
        .saturating_sub(1)
        .max(surf.first_wet);
    let i_hi = ((d_hi * surf.inv_step).max(0.0).min(nt as f64) as usize + 2).min(nt);
    if i_lo >= i_hi {
        return None;
    }
    let k_path = (1.0 + back) / den;
    let x1 = -ALPHA_PER_MM * k_path * surf.step_mm;
    let att = [
        exp_small(-ALPHA_PER_MM * k_path * (i_lo as f64 * surf.step_mm + a)),
        exp_small(x1),
        exp_small(8.0 * x1),
    ];
    Some((rd, rfl, t, w, i_lo, i_hi, att))
}

/// Every ray's set-up, on every tier this CPU runs, has the bits of the formulas ray by
/// ray (the tracer's before the set-up moved here), over random surfaces of both
/// geometries and three media; the vector search for the bubble layers settles for
/// nearly every ray and then agrees with the search ray by ray.
#[test]
fn setup_matches_the_ray_by_ray_formulas() {
    let mut rng = Pcg32::new(11, 3);
    let tiers: Vec<Isa> = [Isa::Baseline, Isa::Avx2, Isa::Avx512]
        .into_iter()
        .filter(|&t| t <= isa())
        .collect();
    let (mut rays_checked, mut unsettled, mut traced) = (0usize, 0usize, 0usize);
    for geometry in [Geometry::ThesisCh3, Geometry::ThesisCh5] {
        for ice in [IceKind::Rime, IceKind::Glazed, IceKind::Water] {
            let cfg = SimConfig::new(ice, SensorKind::B, geometry);
            let m = SensorModel::new(&cfg);
            let nt = m.thick.len();
            for _ in 0..6 {
                let lim = 20f64.to_radians();
                let (tx, ty) = (
                    (lim * (2.0 * uniform(&mut rng) - 1.0)).tan(),
                    (lim * (2.0 * uniform(&mut rng) - 1.0)).tan(),
                );
                let surf = Surface {
                    tx,
                    ty,
                    normal: DVec3::new(-tx, -ty, 1.0).normalize(),
                    centre_x_mm: geometry.centre_x_mm(),
                    n_medium: cfg.params.n_medium,
                    step_mm: cfg.step_mm,
                    inv_step: 1.0 / cfg.step_mm,
                    first_wet: 1,
                    nt,
                    x_hi: geometry.length_b_mm() + geometry.radius_mm(),
                    y_hi: geometry.radius_mm(),
                };
                for &tier in &tiers {
                    let mut su = RaySetups::default();
                    with_isa(tier, || su.compute(&m.ray_lanes, &surf, true, true));
                    for (r, ray) in m.rays.iter().enumerate() {
                        let (p0, v) = (ray.p0, ray.dir);
                        let a = tx * (p0.x - surf.centre_x_mm) + ty * p0.y;
                        let den = v.z - tx * v.x - ty * v.y;
                        let slope = DVec2::new(v.x, v.y) / v.z;
                        let off1 = tx * slope.x + ty * slope.y;
                        let at = format!("{geometry:?} {ice:?} {tier:?} ray {r}");
                        assert_eq!(su.a[r].to_bits(), a.to_bits(), "{at}");
                        assert_eq!(su.den[r].to_bits(), den.to_bits(), "{at}");
                        assert_eq!(su.slope_x[r].to_bits(), slope.x.to_bits(), "{at}");
                        assert_eq!(su.slope_y[r].to_bits(), slope.y.to_bits(), "{at}");
                        assert_eq!(su.off1[r].to_bits(), off1.to_bits(), "{at}");
                        let bray = BubbleRay {
                            p0,
                            slope_xy: slope,
                            a,
                            off1,
                            inv_step: surf.inv_step,
                            first_wet: 1,
                        };
                        let j_end = layers_covered(&|j: u32| bray.cover_steps(f64::from(j)), 1, nt);
                        if su.layers[r] < 0.0 {
                            unsettled += 1;
                        } else {
                            assert_eq!(su.layers[r], f64::from(j_end), "{at}");
                        }
                        let want = specular_by_ray(p0, v, &surf, a, den);
                        assert_eq!(su.spec_ok[r] != 0.0, want.is_some(), "{at}");
                        if let Some((rd, rfl, t, w, i_lo, i_hi, [att, step, step8])) = want {
                            let got = [
                                su.rd_x[r],
                                su.rd_y[r],
                                su.rd_z[r],
                                su.rfl[r],
                                su.fibre_t[r],
                                su.w_x[r],
                                su.w_y[r],
                                su.att[r],
                                su.att_step[r],
                                su.att_step8[r],
                            ];
                            let want = [rd.x, rd.y, rd.z, rfl, t, w.x, w.y, att, step, step8];
                            for (g, w) in got.iter().zip(&want) {
                                assert_eq!(g.to_bits(), w.to_bits(), "{at}: {got:?} {want:?}");
                            }
                            assert_eq!(
                                (su.i_lo[r] as usize, su.i_hi[r] as usize),
                                (i_lo, i_hi),
                                "{at}"
                            );
                            traced += 1;
                        }
                        rays_checked += 1;
                    }
                }
            }
        }
    }
    // Most rays reflect onto the face; the vector search leaves almost none to the
    // search ray by ray.
    assert!(traced * 4 > rays_checked, "{traced} of {rays_checked}");
    assert!(
        unsettled * 1000 < rays_checked,
        "{unsettled} of {rays_checked}"
    );
}
