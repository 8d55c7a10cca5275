//! Golden values: the tracer's output, bit for bit, for fixed seeds.
//!
//! The firmware embeds a response table generated from this Monte Carlo, and speed work on
//! the tracer must not move a single bit of it. Each case below is hashed over every f64 of
//! its output (FNV-1a over `f64::to_bits`, in a fixed order) and a few values are compared
//! exactly. A failure prints the whole table as it is now, ready to paste — but only paste
//! it when the physics was changed on purpose, and say so in the commit.
//!
//! The values depend on the platform's libm (`exp`, `ln`, `tan`, `sin_cos`, `sqrt`); they
//! were taken on x86_64 Linux (glibc), where CI runs.

use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, fit_quality};
use fois_sim::*;

/// FNV-1a, 64 bit, over the bit patterns of a sequence of f64.
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn f(&mut self, x: f64) {
        for b in x.to_bits().to_le_bytes() {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn fs(&mut self, xs: &[f64]) {
        for &x in xs {
            self.f(x);
        }
    }
}

fn hash_curve(h: &mut Fnv, c: &Curve) {
    for p in &c.points {
        h.fs(&[
            p.thickness_mm,
            p.i1_ua,
            p.i2_ua,
            p.i1_refl_ua,
            p.i1_scat_ua,
            p.i2_refl_ua,
            p.i2_scat_ua,
        ]);
    }
}

fn hash_mc(h: &mut Fnv, pts: &[McPoint]) {
    for p in pts {
        h.fs(&[p.thickness_mm, p.mean_ua[0], p.mean_ua[1]]);
        h.fs(&[
            p.cov_ua2[0][0],
            p.cov_ua2[0][1],
            p.cov_ua2[1][0],
            p.cov_ua2[1][1],
        ]);
    }
}

fn hash_crlb(h: &mut Fnv, pts: &[CrlbPoint]) {
    for p in pts {
        h.fs(&[p.thickness_mm, p.mu_ua[0], p.mu_ua[1]]);
        h.fs(&[p.dmu_ua_per_mm[0], p.dmu_ua_per_mm[1]]);
        h.fs(&[p.sigma_ua2[0][0], p.sigma_ua2[0][1], p.sigma_ua2[1][1]]);
        h.fs(&[
            p.dsigma_ua2_per_mm[0][0],
            p.dsigma_ua2_per_mm[0][1],
            p.dsigma_ua2_per_mm[1][1],
        ]);
        h.fs(&[p.crlb_std_mm, p.crlb_no_dsigma_std_mm]);
        h.fs(&[p.residual_ua[0], p.residual_ua[1]]);
    }
}

/// One case as computed now: its hash and a few exact values.
#[derive(Debug, PartialEq)]
struct Got {
    name: &'static str,
    hash: u64,
    values: Vec<f64>,
}

fn cfg(ice: IceKind, sensor: SensorKind) -> SimConfig {
    SimConfig::new(ice, sensor, Geometry::ThesisCh5)
}

/// Single accretions: (name, config, seed, run).
fn curve_cases() -> Vec<(&'static str, SimConfig, u64, u64)> {
    let mut v = vec![
        ("rime_b", cfg(IceKind::Rime, SensorKind::B), 1, 0),
        ("rime_b_run_7", cfg(IceKind::Rime, SensorKind::B), 3, 7),
        ("glazed_b", cfg(IceKind::Glazed, SensorKind::B), 1, 0),
        ("glazed_b_run_5", cfg(IceKind::Glazed, SensorKind::B), 42, 5),
        ("water_b", cfg(IceKind::Water, SensorKind::B), 1, 0),
        ("flat_b", cfg(IceKind::Flat, SensorKind::B), 1, 0),
        ("rime_a", cfg(IceKind::Rime, SensorKind::A), 1, 0),
        ("glazed_a", cfg(IceKind::Glazed, SensorKind::A), 2, 1),
        ("flat_a", cfg(IceKind::Flat, SensorKind::A), 1, 0),
    ];
    let mut c = cfg(IceKind::Glazed, SensorKind::B);
    c.diffuse_fresnel = DiffuseFresnel::MeanSurface;
    v.push(("glazed_b_mean_surface_fresnel", c, 1, 0));
    let mut c = cfg(IceKind::Glazed, SensorKind::B);
    c.params.diffuse_max_rad = 0.0;
    v.push(("glazed_b_no_diffuse", c, 1, 0));
    let mut c = cfg(IceKind::Rime, SensorKind::B);
    c.params.diffuse_max_rad = 20f64.to_radians();
    v.push(("rime_b_diffuse_20deg", c, 4, 2));
    let mut c = cfg(IceKind::Glazed, SensorKind::B);
    c.coupling = Coupling::AcceptanceCone;
    v.push(("glazed_b_acceptance", c, 1, 0));
    let mut c = cfg(IceKind::Rime, SensorKind::B);
    c.coupling = Coupling::AcceptanceCone;
    v.push(("rime_b_acceptance", c, 1, 0));
    let mut c = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh3);
    c.step_mm = 0.25;
    c.max_mm = 12.0;
    v.push(("rime_b_ch3_step_0_25", c, 5, 3));
    let mut c = SimConfig::new(IceKind::Flat, SensorKind::B, Geometry::ThesisCh3);
    c.fibre_spread = false;
    v.push(("flat_b_ch3_no_spread", c, 1, 0));
    let mut c = cfg(IceKind::Glazed, SensorKind::B);
    c.fibre_seed = 99;
    c.max_mm = 40.0;
    v.push(("glazed_b_fibre_seed_99_40mm", c, 6, 0));
    v
}

fn compute_curve(name: &'static str, c: &SimConfig, seed: u64, run: u64) -> Got {
    let curve = accretion_curve(c, seed, run);
    let mut h = Fnv::new();
    hash_curve(&mut h, &curve);
    let n = curve.points.len();
    let mut values = Vec::new();
    for i in [n / 10, n / 4, n / 2, n - 1] {
        let p = curve.points[i];
        values.extend([p.i1_ua, p.i2_ua]);
    }
    Got {
        name,
        hash: h.0,
        values,
    }
}

fn compute_mc(name: &'static str, c: &SimConfig, runs: u64, seed: u64) -> Got {
    let mc = monte_carlo(c, runs, seed, &|| {});
    let bound = crlb(&mc.points, DEFAULT_FIT_HALF_WIDTH_MM);
    let q = fit_quality(&mc.points, &bound, runs as usize);
    let mut h = Fnv::new();
    for r in &mc.runs {
        hash_curve(&mut h, r);
    }
    hash_mc(&mut h, &mc.points);
    hash_crlb(&mut h, &bound);
    h.fs(&q.rms_residual_ua);
    h.fs(&q.rms_std_error_ua);
    let n = mc.points.len();
    let mut values = Vec::new();
    for i in [n / 5, n - 1] {
        let p = mc.points[i];
        values.extend([p.mean_ua[0], p.mean_ua[1], p.cov_ua2[0][0], p.cov_ua2[0][1]]);
        values.extend([p.cov_ua2[1][1], bound[i].crlb_std_mm]);
    }
    Got {
        name,
        hash: h.0,
        values,
    }
}

/// Bit for bit (NaN equals NaN).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// Compare, and on a mismatch print the whole table as it is now.
fn check(got: &[Got], want: &[(&str, u64, &[f64])]) {
    let same = got.len() == want.len()
        && got
            .iter()
            .zip(want)
            .all(|(g, w)| g.name == w.0 && g.hash == w.1 && same_bits(&g.values, w.2));
    if !same {
        let mut table = String::new();
        for g in got {
            table += &format!(
                "    (\n        {:?},\n        {:#018x},\n        &[",
                g.name, g.hash
            );
            for v in &g.values {
                if v.is_nan() {
                    table += "f64::NAN, ";
                } else {
                    table += &format!("{v:?}, ");
                }
            }
            table += "],\n    ),\n";
        }
        for (g, w) in got.iter().zip(want) {
            if g.name != w.0 || g.hash != w.1 || !same_bits(&g.values, w.2) {
                eprintln!(
                    "CHANGED {}: hash {:#018x} (golden {:#018x})",
                    g.name, g.hash, w.1
                );
                for (a, b) in g.values.iter().zip(w.2) {
                    if !same_bits(&[*a], &[*b]) {
                        eprintln!("    {a:?} (golden {b:?}, diff {:e})", a - b);
                    }
                }
            }
        }
        panic!("output differs from the golden values; now:\n{table}");
    }
}

#[test]
fn single_accretions_are_bit_identical_to_the_golden_values() {
    let got: Vec<Got> = curve_cases()
        .iter()
        .map(|(n, c, s, r)| compute_curve(n, c, *s, *r))
        .collect();
    check(&got, GOLDEN_CURVES);
}

/// Every instruction-set tier of the kernels that this CPU runs (AVX-512, AVX2, the
/// baseline) gives the golden values, bit for bit: the tiers differ in speed only.
#[test]
fn every_kernel_tier_gives_the_golden_values() {
    let tiers: Vec<Isa> = [Isa::Baseline, Isa::Avx2, Isa::Avx512]
        .into_iter()
        .filter(|&t| t <= isa())
        .collect();
    // CI runs on x86-64 with AVX2 at least: a build that loses the tiers must not pass.
    #[cfg(target_arch = "x86_64")]
    assert!(tiers.len() >= 2, "only {tiers:?} on this CPU");
    for tier in tiers {
        let got: Vec<Got> = with_isa(tier, || {
            assert_eq!(isa(), tier, "the cap holds on this thread");
            curve_cases()
                .iter()
                .map(|(n, c, s, r)| compute_curve(n, c, *s, *r))
                .collect()
        });
        eprintln!("tier {}", tier.name());
        check(&got, GOLDEN_CURVES);
    }
}

#[test]
fn monte_carlo_and_crlb_are_bit_identical_to_the_golden_values() {
    let mut short = cfg(IceKind::Glazed, SensorKind::A);
    short.max_mm = 6.0;
    let got = vec![
        // The thesis Monte Carlo (`foisctl sim crlb --ice rime --runs 1000`, seed 1).
        compute_mc("rime_b_1000", &cfg(IceKind::Rime, SensorKind::B), 1000, 1),
        compute_mc("glazed_b_200", &cfg(IceKind::Glazed, SensorKind::B), 200, 1),
        compute_mc("water_b_20", &cfg(IceKind::Water, SensorKind::B), 20, 3),
        compute_mc("glazed_a_6mm_50", &short, 50, 11),
    ];
    check(&got, GOLDEN_MC);
}

const GOLDEN_CURVES: &[(&str, u64, &[f64])] = &[
    (
        "rime_b",
        0xf581741b0c2a1446,
        &[
            16.650473194784926,
            1.071365243072774,
            24.368529431138654,
            6.458035150336952,
            28.339064253704006,
            10.143193959273006,
            30.343653751362055,
            11.577597681172607,
        ],
    ),
    (
        "rime_b_run_7",
        0x1a62973a7e901337,
        &[
            22.80646939686988,
            2.6317585701940125,
            23.14421217478686,
            10.037951923846723,
            28.194045442801272,
            9.907371755192553,
            30.265549825342642,
            11.75555851717786,
        ],
    ),
    (
        "glazed_b",
        0x6c70d3ed08ab16df,
        &[
            9.642299130859682,
            1.600325248485175,
            3.6509163310654076,
            4.744886008278293,
            0.9521584808000838,
            1.6292771146330638,
            0.2839159037732232,
            0.3191695117637108,
        ],
    ),
    (
        "glazed_b_run_5",
        0xf190765a703ffe1d,
        &[
            53.69958341661101,
            23.534115976999797,
            1.993043108549696,
            14.641542476891527,
            0.241766099063573,
            0.3498748291216227,
            0.26618437913374493,
            0.12219705391780392,
        ],
    ),
    (
        "water_b",
        0x131e2bef9ce1ead9,
        &[
            21.360843426646134,
            2.9099480925437793,
            3.7477446908023646,
            11.89216077440896,
            0.041909769351676895,
            0.7909626186648964,
            0.0,
            0.01065056882399794,
        ],
    ),
    (
        "flat_b",
        0x25ef8043231a6925,
        &[
            20.01131650815001,
            3.6003374694787276,
            3.141066815827438,
            10.657099276708022,
            0.030305225381217816,
            0.6283086853910281,
            0.0,
            0.007618260800035018,
        ],
    ),
    (
        "rime_a",
        0xc308a722986398c8,
        &[
            17.84294663279357,
            1.301026794096661,
            25.561002869147295,
            6.687696701360839,
            29.53153769171265,
            10.372855510296892,
            31.5361271893707,
            11.807259232196495,
        ],
    ),
    (
        "glazed_a",
        0xf008798308612fb6,
        &[
            59.171039172149214,
            30.62947460513729,
            3.2414335255699553,
            13.95768504686143,
            1.467293330204821,
            0.5963436308872295,
            1.4699395046973593,
            0.3922959929212298,
        ],
    ),
    (
        "flat_a",
        0x20e909139adbbcd5,
        &[
            21.203789946158654,
            3.8299990205026146,
            4.333540253836082,
            10.886760827731909,
            1.2227786633898625,
            0.8579702364149152,
            1.1924734380086446,
            0.23727981182392213,
        ],
    ),
    (
        "glazed_b_mean_surface_fresnel",
        0xa6c7ca46177d8bd8,
        &[
            5.420149620412759,
            0.32471016511253564,
            3.6796052161773556,
            2.316048943763252,
            1.0136195616297905,
            1.695125448790838,
            0.28486095554799085,
            0.3275728899953893,
        ],
    ),
    (
        "glazed_b_no_diffuse",
        0x476481c9c6049e8e,
        &[
            5.538009346447772,
            0.27470663854841404,
            4.6873350448624125,
            1.9865180874684163,
            0.6691595479188056,
            2.540154596636166,
            0.25989639211671917,
            0.23761283817743623,
        ],
    ),
    (
        "rime_b_diffuse_20deg",
        0x498cd8c3eb87102d,
        &[
            65.72752770733801,
            27.563475008335192,
            21.48786540995446,
            15.358025532731334,
            28.259789530257507,
            10.367050398589786,
            29.964054897451025,
            12.307503030040257,
        ],
    ),
    (
        "glazed_b_acceptance",
        0x57db57e6ba60afda,
        &[
            0.002656472476533698,
            0.0,
            0.01647071918405685,
            0.0,
            0.029741886381730694,
            0.0,
            0.05759462912726134,
            0.007599604032997021,
        ],
    ),
    (
        "rime_b_acceptance",
        0xcd47fcdce30cf075,
        &[
            0.27984902234286735,
            0.0,
            0.9483848839916741,
            0.0,
            2.196281789696668,
            0.051573456429280184,
            3.3684994932837946,
            0.4066898412922815,
        ],
    ),
    (
        "rime_b_ch3_step_0_25",
        0x467e496a013dcdef,
        &[
            39.24553640288462,
            0.3082310515166532,
            26.391507964350247,
            7.58796510542094,
            29.53584192740164,
            3.4309212026397797,
            31.50179369213916,
            4.267085648962982,
        ],
    ),
    (
        "flat_b_ch3_no_spread",
        0x01b7011e867837c1,
        &[
            12.54127242096439,
            0.0,
            1.3103254843621348,
            9.287219222496146,
            0.0,
            0.0,
            0.0,
            0.0,
        ],
    ),
    (
        "glazed_b_fibre_seed_99_40mm",
        0xbf9096fbf8d3321f,
        &[
            1.6832430707544868,
            8.284451301243122,
            0.2951036347392372,
            0.2393387365467187,
            0.2972554807847122,
            0.16260428085990283,
            0.30294959040405217,
            0.16210276319373731,
        ],
    ),
];

const GOLDEN_MC: &[(&str, u64, &[f64])] = &[
    (
        "rime_b_1000",
        0x0c93beac8fd2e17c,
        &[
            23.307522340007733,
            16.634572344757753,
            1.0912128700366281,
            10.30863584071417,
            130.08180797384364,
            0.22174247704141056,
            29.992561104799396,
            12.083568157047363,
            0.1335908490894327,
            -0.0037885250600027086,
            0.04888313233380841,
            2.5518547437282084,
        ],
    ),
    (
        "glazed_b_200",
        0x12ab55997461eaf9,
        &[
            5.9062093247977145,
            19.815682238212343,
            2.076691790769405,
            8.191387832329811,
            107.13415576846086,
            0.19352628933794339,
            0.33327048799742487,
            0.2443335015681982,
            0.0036842076952242624,
            0.005067562002491139,
            0.017421994398101506,
            1.6496159731123352,
        ],
    ),
    (
        "water_b_20",
        0x2962352b33455e0e,
        &[
            7.631837554901568,
            14.820686868926453,
            8.30379900232644e-31,
            -3.321519600930576e-30,
            1.3286078403722303e-29,
            f64::NAN,
            0.0,
            0.010650568823997945,
            0.0,
            0.0,
            2.8508831413626844e-35,
            f64::NAN,
        ],
    ),
    (
        "glazed_a_6mm_50",
        0xf977dcf179cfe3ee,
        &[
            40.79458964592415,
            9.852781112974919,
            377.81862035129444,
            127.86707050399052,
            47.7473857081108,
            0.15704292615011914,
            1.981172414360282,
            2.0090999486656638,
            0.28707054880414096,
            0.34415518581603205,
            0.5685227004252177,
            0.6042543214921631,
        ],
    ),
];
