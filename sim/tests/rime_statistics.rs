//! The rime Monte Carlo against reference statistics recorded with the earlier random-stream
//! layout.
//!
//! Before the counter-based streams the bubbles of a ray were drawn layer by layer from a PCG stream; now they
//! are walked gap by gap from a counter-based stream (`bubbles.rs`). The golden values of
//! `golden.rs` hold the new layout bit for bit; this test holds the *statistics* to the old
//! one: the mean and variance of (I1, I2) over accretions at six thicknesses, recorded from
//! 20 × 1000 accretions of the old layout (seeds 9001–9020, commit 3a4ba31), each with its
//! standard error (the spread of the 20 batch values / √20). A change of the physics or of
//! the sampling that moves these by more than 4 combined standard errors fails here, even
//! when it is made on purpose and the golden values are renewed. The full comparison (every
//! thickness, the CRLB too) is the study in `sim/studies/`, summarised in sim/README.

use fois_sim::*;

/// (thickness mm, [(mean I1 µA, SE), (mean I2 µA, SE), (var I1 µA², SE), (var I2 µA², SE)]).
type Reference = (f64, [(f64, f64); 4]);

const OLD_LAYOUT: &[Reference] = &[
    (
        1.0,
        [
            (26.5798, 0.105),
            (0.992434, 0.00499),
            (195.625, 2.03),
            (0.532959, 0.0106),
        ],
    ),
    (
        2.0,
        [
            (30.3821, 0.0917),
            (12.7268, 0.083),
            (148.806, 1.66),
            (117.284, 1.4),
        ],
    ),
    (
        3.0,
        [
            (23.3186, 0.00853),
            (16.8982, 0.085),
            (1.15113, 0.0188),
            (128.761, 1.3),
        ],
    ),
    (
        5.0,
        [
            (25.1564, 0.00364),
            (9.56744, 0.00485),
            (0.215379, 0.00232),
            (0.326476, 0.00306),
        ],
    ),
    (
        10.0,
        [
            (29.2668, 0.00292),
            (11.2425, 0.00163),
            (0.147164, 0.0014),
            (0.0531402, 0.000403),
        ],
    ),
    (
        15.0,
        [
            (29.9999, 0.00286),
            (12.0835, 0.00137),
            (0.137447, 0.00131),
            (0.0492409, 0.00039),
        ],
    ),
];

/// Mean, variance (M − 1) and the standard errors of both, from the samples.
fn moments(x: &[f64]) -> [(f64, f64); 2] {
    let m = x.len() as f64;
    let mean = x.iter().sum::<f64>() / m;
    let c2 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / m;
    let c4 = x.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / m;
    let var = c2 * m / (m - 1.0);
    // Var(sample variance) ≈ (μ₄ − σ⁴)/M: heavy tails (1–3 mm) make it much larger than
    // the Gaussian 2σ⁴/M.
    [(mean, (var / m).sqrt()), (var, ((c4 - c2 * c2) / m).sqrt())]
}

/// (I1, I2) of every accretion at thickness `d`, µA.
fn currents_at(mc: &MonteCarlo, d: f64) -> (Vec<f64>, Vec<f64>) {
    let i = mc
        .points
        .iter()
        .position(|p| (p.thickness_mm - d).abs() < 1e-9)
        .unwrap_or_else(|| panic!("no point at {d} mm"));
    mc.runs
        .iter()
        .map(|c| (c.points[i].i1_ua, c.points[i].i2_ua))
        .unzip()
}

#[test]
fn rime_mean_and_variance_agree_with_the_old_stream_layout() {
    let cfg = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let runs = 1000;
    let mc = monte_carlo(&cfg, runs, 4242, &|| {});
    let mut report = String::new();
    let mut worst: f64 = 0.0;
    for &(d, reference) in OLD_LAYOUT {
        let (i1, i2) = currents_at(&mc, d);
        let [m1, v1] = moments(&i1);
        let [m2, v2] = moments(&i2);
        for (name, (got, se_got), (want, se_want)) in [
            ("mean I1", m1, reference[0]),
            ("mean I2", m2, reference[1]),
            ("var I1", v1, reference[2]),
            ("var I2", v2, reference[3]),
        ] {
            let z = (got - want) / se_got.hypot(se_want);
            worst = worst.max(z.abs());
            report += &format!("{d:5.1} mm {name}: {got:.5} vs {want:.5} (z {z:+.2})\n");
        }
    }
    assert!(
        worst < 4.0,
        "the rime statistics moved from the old layout:\n{report}"
    );
    // The test can fail: the same check against a reference 3 % off does.
    let (d, reference) = OLD_LAYOUT[3];
    let [(mean, se), _] = moments(&currents_at(&mc, d).0);
    let (want, se_want) = reference[0];
    assert!(((mean - 1.03 * want) / se.hypot(se_want)).abs() > 4.0);
}
