//! The scenario format is strict: a misspelt key or a bad value is an error
//! that names the file and the key; overlays split the timeline correctly.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use fois_hil::scenario::{self, ice_start_s};
use fois_vnode::Cover;

const BASE: &str = r#"
class = "rime"
[[segment]]
duration_s = 100
cover = "dry"
[[segment]]
duration_s = 200
cover = "rime"
rate_mm_per_h = 3.6
air_temp_c = -2.0
air_temp_end_c = -6.0
"#;

fn err(extra: &str) -> String {
    let text = format!("{BASE}{extra}");
    match scenario::parse(Path::new("scenarios/bad.toml"), &text) {
        Ok(_) => panic!("accepted: {extra}"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn unknown_keys_are_refused_naming_file_and_key() {
    for (extra, key) in [
        ("[expect]\nalarm_by_mmm = 0.2\n", "alarm_by_mmm"),
        (
            "[[command]]\nat_s = 1\nsend = \"button\"\nwhen = 2\n",
            "when",
        ),
        (
            "[[overlay]]\nstart_s = 1\nduration_s = 1\nambient = [1.0, 1.0]\n",
            "ambient",
        ),
        ("[link]\ncorrupt = 0.1\n", "corrupt"),
        ("[sweep]\nadc_noise_lsb = [1.0]\nupto = 3\n", "upto"),
        ("colour = \"red\"\n", "colour"),
    ] {
        let e = err(extra);
        assert!(
            e.contains("scenarios/bad.toml") && e.contains(key) && e.contains("unknown field"),
            "{extra:?} → {e}"
        );
    }
    // A segment key is checked by the host's parser, with the same strictness.
    let text = BASE.replace("rate_mm_per_h", "rate_mm_h");
    let e = format!(
        "{:#}",
        scenario::parse(Path::new("scenarios/seg.toml"), &text).unwrap_err()
    );
    assert!(
        e.contains("scenarios/seg.toml") && e.contains("rate_mm_h"),
        "{e}"
    );
}

#[test]
fn bad_values_are_refused_with_the_reason() {
    for (extra, words) in [
        ("[config]\nonset_rise_nA = 5\n", "onset_rise_nA"),
        ("[config]\nonset_rise_na = 10\n", "onset_rise_na"),
        ("[config]\nclear_rise_na = 2000\n", "hysteresis"),
        ("[expect]\nevents = [\"ice_onsett\"]\n", "ice_onsett"),
        ("[expect]\nfinal_state = \"frozen\"\n", "frozen"),
        ("[[command]]\nat_s = 1\nsend = \"press\"\n", "press"),
        ("[[command]]\nat_s = 900\nsend = \"button\"\n", "outside"),
        (
            "[[command]]\nat_s = 1\nsend = \"button\"\nrefusal = \"step\"\n",
            "refusal only goes with expect",
        ),
        (
            "[[command]]\nat_s = 1\nsend = \"button\"\nexpect = \"error\"\nrefusal = \"cloudy\"\n",
            "cloudy",
        ),
        (
            "[[overlay]]\nstart_s = 1\nduration_s = 5\nrepeat = 3\nambient_ua = [1.0, 1.0]\n",
            "period_s",
        ),
        ("[[overlay]]\nstart_s = 1\nduration_s = 5\n", "sets nothing"),
        ("[link]\ndrop_probability = 2.0\n", "drop_probability"),
    ] {
        let e = err(extra);
        assert!(
            e.contains("scenarios/bad.toml") && e.contains(words),
            "{extra:?} → {e}"
        );
    }
    // A factory gain calibration the node could not hold.
    for (top, words) in [
        (
            "gain_calibration = [5.0, 0.02]\n",
            "outside the node's range",
        ),
        ("gain_calibration = [1.0, 0.0]\n", "relative sd"),
    ] {
        let e = format!(
            "{:#}",
            scenario::parse(Path::new("scenarios/bad.toml"), &format!("{top}{BASE}")).unwrap_err()
        );
        assert!(
            e.contains("scenarios/bad.toml") && e.contains(words),
            "{top:?} → {e}"
        );
    }
    let ok = scenario::parse(
        Path::new("ok.toml"),
        &format!("gain_calibration = [1.0, 0.02]\n{BASE}"),
    )
    .unwrap();
    assert_eq!(ok[0].file.gain_calibration, Some([1.0, 0.02]));
    let e = format!(
        "{:#}",
        scenario::parse(Path::new("x.toml"), "class = \"icy\"\n").unwrap_err()
    );
    assert!(e.contains("icy"), "{e}");
}

#[test]
fn config_sweep_and_overlays_build_the_expected_timeline() {
    let text = format!(
        "{BASE}[config]\nonset_frames = 10\nstream_on_boot = true\n\
         [sweep]\nadc_noise_lsb = [2.0, 8.0]\nexpect_up_to_lsb = 4.0\n\
         [[overlay]]\nstart_s = 150\nduration_s = 10\nrepeat = 2\nperiod_s = 50\nambient_ua = [9.0, 8.0]\n"
    );
    let runs = scenario::parse(Path::new("scenarios/ok.toml"), &text).unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[0].name, "ok@2lsb");
    assert_eq!((runs[0].checked, runs[1].checked), (true, false));
    let cfg = runs[0].config.as_ref().unwrap();
    assert_eq!(cfg.onset_frames, 10);
    assert_eq!(
        cfg.onset_rise_na,
        fois_protocol::Config::default().onset_rise_na
    );
    let tl = &runs[1].timeline;
    // dry 0–100 | rime 100–150 | sun 150–160 | 160–200 | sun 200–210 | 210–300.
    let segs = tl.segments();
    let starts: Vec<f64> = segs
        .iter()
        .scan(0.0, |t, s| {
            let a = *t;
            *t += s.duration_s;
            Some(a)
        })
        .collect();
    assert_eq!(starts, vec![0.0, 100.0, 150.0, 160.0, 200.0, 210.0]);
    assert_eq!(tl.duration_s(), 300.0);
    assert!(segs.iter().all(|s| s.adc_noise_lsb == 8.0));
    assert_eq!(segs[2].ambient_ua, [9.0, 8.0]);
    assert_eq!(segs[3].ambient_ua, [0.0, 0.0]);
    // The -2 → -6 °C ramp over 100–300 s is split into sub-ramps.
    assert_eq!(segs[1].air_temp_c, -2.0);
    assert!((segs[2].air_temp_c - -3.0).abs() < 1e-12);
    assert!((segs[2].air_temp_end_c.unwrap() - -3.2).abs() < 1e-12);
    assert!((segs[5].air_temp_end_c.unwrap() - -6.0).abs() < 1e-12);
    // Thickness stays continuous across the cuts: 3.6 mm/h = 1 µm/s.
    let env = fois_vnode::Environment::with_curves(tl.clone(), [], [0.0; 2]);
    let t = env.truth(205_000_000_000);
    assert_eq!(t.cover, Cover::Rime);
    assert!((t.thickness_mm - 0.105).abs() < 1e-9, "{}", t.thickness_mm);
    assert_eq!(t.ambient_ua[0], 9.0);
    assert_eq!(ice_start_s(tl), Some(100.0));
}

#[test]
fn a_sweep_runs_every_noise_and_seed_combination() {
    let text = format!(
        "{BASE}seed = 9\n[sweep]\nadc_noise_lsb = [1.0, 50.0]\nseed = [3, 4, 5]\nexpect_up_to_lsb = 10.0\n"
    );
    // `seed` after [[segment]] belongs to the segment: refused by the host's parser.
    assert!(scenario::parse(Path::new("s.toml"), &text).is_err());
    let text = format!(
        "seed = 9\n{BASE}[sweep]\nadc_noise_lsb = [1.0, 50.0]\nseed = [3, 4, 5]\nexpect_up_to_lsb = 10.0\n"
    );
    let runs = scenario::parse(Path::new("s.toml"), &text).unwrap();
    let got: Vec<(String, u64, bool)> = runs
        .iter()
        .map(|r| (r.name.clone(), r.seed, r.checked))
        .collect();
    let want: Vec<(String, u64, bool)> = [1.0, 50.0]
        .iter()
        .flat_map(|&n| {
            [3u64, 4, 5]
                .iter()
                .map(move |&k| (format!("s@{n}lsb@seed{k}"), k, n <= 10.0))
        })
        .collect();
    assert_eq!(got, want);
    assert!(
        runs[3]
            .timeline
            .segments()
            .iter()
            .all(|s| s.adc_noise_lsb == 50.0)
    );
    let one = scenario::parse(Path::new("s.toml"), &format!("seed = 9\n{BASE}")).unwrap();
    assert_eq!((one.len(), one[0].seed, one[0].name.as_str()), (1, 9, "s"));
}

#[test]
fn every_shipped_file_loads() {
    let files = scenario::files_in(&scenario::default_dir()).unwrap();
    assert!(files.len() >= 14, "{} files", files.len());
    for f in files {
        let runs = scenario::load(&f).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(!runs.is_empty());
    }
}

#[test]
fn an_overlay_splits_a_fouling_ramp_and_the_thin_check_needs_accuracy() {
    let text = "class = \"other\"\n[[segment]]\nduration_s = 100\ncover = \"rime\"\n\
                rate_mm_per_h = 3.6\nface_transmission = 1.0\nface_transmission_end = 0.8\n\
                gain_tempco_ppm_per_k = -6000.0\n\
                [[overlay]]\nstart_s = 50\nduration_s = 25\nambient_ua = [5.0, 5.0]\n";
    let runs = scenario::parse(Path::new("f.toml"), text).unwrap();
    let segs = runs[0].timeline.segments();
    // 0–50 | sun 50–75 | 75–100: t 1.0 → 0.9 | 0.9 → 0.85 | 0.85 → 0.8.
    let t: Vec<(f64, f64)> = segs
        .iter()
        .map(|s| (s.face_transmission, s.face_transmission_end.unwrap()))
        .collect();
    let want = [(1.0, 0.9), (0.9, 0.85), (0.85, 0.8)];
    assert_eq!(t.len(), 3);
    for (got, want) in t.iter().zip(want) {
        assert!(
            (got.0 - want.0).abs() < 1e-12 && (got.1 - want.1).abs() < 1e-12,
            "{t:?}"
        );
    }
    assert!(
        segs.iter()
            .all(|s| (s.gain_tempco_per_k + 0.006).abs() < 1e-15)
    );
    // The signal at 60 s: t = 0.88, so × 0.7744 (and the −5 °C default air
    // with κ = −0.6 %/K: × exp(0.18) = 1.197 22).
    let env = fois_vnode::Environment::with_curves(runs[0].timeline.clone(), [], [0.0; 2]);
    let g = env.truth(60_000_000_000).gain;
    assert!((g.signal_gain() - 0.7744 * 1.197_217).abs() < 1e-5, "{g:?}");
    assert!((env.truth(60_000_000_000).ambient_ua[0] - 5.0 * 0.88).abs() < 1e-9);

    let e = err("[expect]\nnot_confidently_thin_from_mm = 4.0\n");
    assert!(e.contains("accuracy = true"), "{e}");
    let ok = format!("accuracy = true\n{BASE}[expect]\nnot_confidently_thin_from_mm = 4.0\n");
    let runs = scenario::parse(Path::new("ok.toml"), &ok).unwrap();
    assert_eq!(runs[0].file.expect.not_confidently_thin_from_mm, Some(4.0));
}

#[test]
fn the_report_reseeds_accuracy_runs_from_a_given_first_seed() {
    let acc = format!("accuracy = true\n{BASE}[sweep]\nseed = [21, 22]\n");
    let mut all = scenario::parse(Path::new("acc.toml"), &acc).unwrap();
    all.extend(scenario::parse(Path::new("plain.toml"), BASE).unwrap());
    let out = scenario::for_accuracy(all, Some(3), 231, Some(100));
    let got: Vec<(String, u64, Option<u32>)> = out
        .iter()
        .map(|s| {
            (
                s.name.clone(),
                s.seed,
                s.config.as_ref().map(|c| c.frame_period_ms),
            )
        })
        .collect();
    let want: Vec<(String, u64, Option<u32>)> = vec![
        ("acc@seed231".into(), 231, Some(100)),
        ("acc@seed232".into(), 232, Some(100)),
        ("acc@seed233".into(), 233, Some(100)),
        ("plain".into(), 1, None),
    ];
    assert_eq!(got, want);
}

/// One format for both: every shipped file loads through the virtual node's
/// reader (`foisctl virtual-node --scenario`), which builds the same
/// timeline (overlays applied), sensor, seed, gain calibration and config
/// as the suite does for the file's own seed and noise.
#[test]
fn every_shipped_file_runs_the_same_on_the_virtual_node() {
    let files = scenario::files_in(&scenario::default_dir()).unwrap();
    assert_eq!(files.len(), 52, "hil/scenarios holds 52 files");
    let mut compared = 0;
    for path in &files {
        let v = fois_vnode::scenario::load(path).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(
            v.ignored.contains(&"class"),
            "{}: class is the suite's key",
            path.display()
        );
        let runs = scenario::load(path).unwrap();
        let hil = &runs[0];
        assert_eq!(v.sensor, hil.sensor, "{}", path.display());
        assert_eq!(v.config, hil.config, "{}", path.display());
        let sweep = hil.file.sweep.as_ref();
        if sweep.is_none_or(|s| s.seed.is_empty()) {
            assert_eq!(v.seed, hil.seed, "{}", path.display());
        }
        if sweep.is_none_or(|s| s.adc_noise_lsb.is_empty()) {
            assert_eq!(v.timeline, hil.timeline, "{}", path.display());
            compared += 1;
        }
    }
    assert!(compared >= 40, "{compared} timelines compared");
}
