//! The estimator's settings ([`EstimatorParams`]): library settings with
//! documented defaults (the board and the virtual node pass them), not part
//! of the protocol `Config`; out-of-range values take their defaults.

/// The estimator's settings. Library settings with documented defaults (the
/// board and the virtual node pass them); they are not part of the protocol
/// `Config`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorParams {
    /// Forgetting time constant τ, s: the posterior carries about one
    /// observation's worth of the last τ of frames (default 30 s).
    pub forget_time_s: f32,
    /// Largest accretion rate, mm/h (default 10: severe in-cloud icing).
    pub max_growth_mm_per_h: f32,
    /// Largest melting / evaporation rate, mm/h (default 5).
    pub max_shrink_mm_per_h: f32,
    /// Rate of shedding (the whole layer falls off), per hour (default 0.1:
    /// a shed shows as a jump of the currents and is taken at once; thick
    /// clear ice, which reads almost like a dry face, is not shed by the
    /// prior alone within hours).
    pub shed_per_h: f32,
    /// Rate of a change of medium at the same thickness, per hour (default 0.5).
    pub switch_per_h: f32,
    /// Measurement noise and baseline uncertainty of I1, I2 (standard
    /// deviation), µA (default 0.15 µA: ~2 ADC steps at 10 kΩ; covers the
    /// frame noise, the worst mains-flicker residual after averaging, and a
    /// baseline drift).
    pub noise_ua: [f32; 2],
    /// Relative standard deviation of the gain calibration (LED flux ×
    /// responsivity against the simulator's absolute scale) (default 0.02).
    pub gain_sd: f32,
    /// Ice is plausible up to this air temperature, °C (default +1.0: the
    /// NTC's ±0.5 K and ice that is still melting).
    pub ice_max_c: f32,
    /// Water is plausible down to this air temperature, °C (default −1.0).
    pub water_min_c: f32,
    /// Width of both temperature transitions, K (default 0.5).
    pub temp_scale_c: f32,
    /// Scale of the prior of a water film's thickness, mm: films drain, so
    /// P(d) ∝ exp(−d / scale) (default 1.0 mm). Ice has a flat prior.
    pub water_scale_mm: f32,
    /// A frame whose currents are further than this squared Mahalanobis
    /// distance from every state fits no state and is skipped (default 50:
    /// p ≈ 10⁻¹¹ for a correct model).
    pub outlier_distance2: f32,
    /// The filter updates once per this period on the robust mean of the
    /// frames gathered in it, s (default 1.0: ten frames at 10 Hz; the
    /// alarm rule still runs every frame).
    pub update_period_s: f32,
    /// Memory of the gain's evidence, s of frames that tell the gain
    /// hypotheses apart (default 3600: one accretion's deviations persist
    /// along it, so the evidence is one observation's worth per hour).
    pub gain_memory_s: f32,
    /// Smallest relative gain spread within one gain hypothesis (default
    /// 0.02): a calibrated gain's hypotheses lie close together, each with
    /// at least this spread, so that none alone claims the ice is where the
    /// table's narrowest states sit (thick rime reads like 2 mm of rime at
    /// a few per cent more gain).
    pub gain_within_min: f32,
    /// The growth history beside the bank (`history.rs`).
    pub history: HistoryParams,
}

impl Default for EstimatorParams {
    fn default() -> Self {
        EstimatorParams {
            forget_time_s: 30.0,
            max_growth_mm_per_h: 10.0,
            max_shrink_mm_per_h: 5.0,
            shed_per_h: 0.1,
            switch_per_h: 0.5,
            noise_ua: [0.15, 0.15],
            gain_sd: 0.02,
            ice_max_c: 1.0,
            water_min_c: -1.0,
            temp_scale_c: 0.5,
            water_scale_mm: 1.0,
            outlier_distance2: 50.0,
            update_period_s: 1.0,
            gain_memory_s: 3600.0,
            gain_within_min: 0.02,
            history: HistoryParams::default(),
        }
    }
}

/// `x` if finite and within `lo..=hi`, else `default`.
#[inline(never)]
pub(super) fn within(x: f32, lo: f32, hi: f32, default: f32) -> f32 {
    if x.is_finite() && x >= lo && x <= hi {
        x
    } else {
        default
    }
}

impl EstimatorParams {
    /// Every field in its valid range; a field that is not (NaN, negative,
    /// absurd) takes its default.
    #[inline(never)]
    pub fn sanitized(self) -> Self {
        let d = EstimatorParams::default();
        EstimatorParams {
            forget_time_s: within(self.forget_time_s, 0.1, 86_400.0, d.forget_time_s),
            max_growth_mm_per_h: within(
                self.max_growth_mm_per_h,
                0.0,
                1_000.0,
                d.max_growth_mm_per_h,
            ),
            max_shrink_mm_per_h: within(
                self.max_shrink_mm_per_h,
                0.0,
                1_000.0,
                d.max_shrink_mm_per_h,
            ),
            shed_per_h: within(self.shed_per_h, 0.0, 3_600.0, d.shed_per_h),
            switch_per_h: within(self.switch_per_h, 0.0, 3_600.0, d.switch_per_h),
            noise_ua: [
                within(self.noise_ua[0], 0.001, 100.0, d.noise_ua[0]),
                within(self.noise_ua[1], 0.001, 100.0, d.noise_ua[1]),
            ],
            gain_sd: within(self.gain_sd, 0.0, 1.0, d.gain_sd),
            ice_max_c: within(self.ice_max_c, -50.0, 50.0, d.ice_max_c),
            water_min_c: within(self.water_min_c, -50.0, 50.0, d.water_min_c),
            temp_scale_c: within(self.temp_scale_c, 0.01, 20.0, d.temp_scale_c),
            water_scale_mm: within(self.water_scale_mm, 0.01, 1_000.0, d.water_scale_mm),
            outlier_distance2: within(self.outlier_distance2, 1.0, 1.0e6, d.outlier_distance2),
            update_period_s: within(self.update_period_s, 0.0, 60.0, d.update_period_s),
            gain_memory_s: within(self.gain_memory_s, 1.0, 1.0e7, d.gain_memory_s),
            gain_within_min: within(self.gain_within_min, 0.0, 0.5, d.gain_within_min),
            history: self.history.sanitized(),
        }
    }
}

/// The history's settings (library settings with documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HistoryParams {
    /// Off: the estimator's output is the bank's alone (the design before).
    pub enabled: bool,
    /// The history updates once per this period, s (default 10: its seven parts run one a second).
    pub period_s: f32,
    /// Rate of a step of the rate to a neighbouring bin, per hour (default 1).
    pub rate_walk_per_h: f32,
    /// Growth pauses at this rate, per hour (default 0.2; 0: no pause
    /// state — the design without it).
    pub pause_per_h: f32,
    /// A dry face starts growing at this rate, per hour (default 1: the
    /// onset of an icing event).
    pub resume_per_h: f32,
    /// Paused growth on ice resumes at this rate, per hour (default 0.3:
    /// ice stays on the face for hours after an icing event ends).
    pub resume_ice_per_h: f32,
    /// The ice sheds to a dry face at this rate, per hour (default 0.1, as
    /// the bank's `shed_per_h`).
    pub shed_per_h: f32,
    /// Share of the probability that restarts anywhere, per hour (default
    /// 0.1): the model's escape.
    pub restart_per_h: f32,
    /// Looks of the bank's evidence per mm of expected growth (default 0.3:
    /// one look per ~3 mm).
    pub looks_per_mm: f32,
    /// Extra looks per mm in the first `early_mm` of an accretion, scaled
    /// by the bank's probability of rime (default 0.7): rime's thin layers
    /// are where its history resolves the most; glazed ice does not get it.
    pub early_rime_looks_per_mm: f32,
    /// Thickness below which the early trust acts, mm (default 1.5).
    pub early_mm: f32,
    /// Looks per hour of time, whatever the growth (default 1): a dry face,
    /// a pause, a stop are seen in time.
    pub looks_per_h: f32,
    /// Prior weight of "the history is wrong" in the output (default 0.05):
    /// where the bank's evidence falls outside what the history foresaw,
    /// the output is the bank's.
    pub escape: f32,
    /// Exponent of the history's marginal in the output (default 0.35): the
    /// history is itself built of tempered looks at the same bank; at full
    /// weight its product with the bank's narrow, wrong branches (rime read
    /// as glaze at 1–3 mm) was confident.
    pub output_weight: f32,
    /// Length of the change look's windows, s (default 240): the currents'
    /// mean over one window against the previous one's.
    pub change_window_s: f32,
    /// Noise of the change between two windows' means (flicker, baseline
    /// drift), per channel, µA (default 0.05).
    pub change_noise_ua: f32,
    /// Relative spread of an accretion's slope dμ/dd against the table's
    /// (default 0.8: at 0.3 the icing period's worst clearing after
    /// 2 mm/h of rime or glaze stopped at 6 mm, or 10 mm/h of rime at
    /// 11 mm, took 27–35 min instead of 19–23 min).
    pub change_slope_sd: f32,
    /// The change look's weight on the rates within a level (its ln
    /// likelihood ratios against the level's best rate times this; default
    /// 0.7): an accretion's slope deviates from the table's alike from
    /// window to window, so the looks' rate evidence is not independent.
    /// 0: each rate its own ratio capped at e^±6 — the look as it was
    /// first, whose rates drifted low (firmware/README.md, *The change
    /// look*). At 1 a replay of rows 180 s apart gave 0.36 RMS ln one hour
    /// into 2 mm/h of rime but 1 Hz rime at 4 mm/h overshot by 20 %; at
    /// 0.5, 0.46 (10 curves of seed 7100, HIL seeds 7001–7003, 2026-11-28).
    pub change_rate_temper: f32,
    /// The node can tell growth from a pause when the change looks of
    /// 20 min (the clearing goal) are worth at least this many nats if the ice grew as
    /// the history believes (default 2); below, the icing state is
    /// "uncertain" and the icing period ends.
    pub tell_nats: f32,
}

impl Default for HistoryParams {
    fn default() -> Self {
        HistoryParams {
            enabled: true,
            period_s: 10.0,
            rate_walk_per_h: 1.0,
            pause_per_h: 0.2,
            resume_per_h: 1.0,
            resume_ice_per_h: 0.3,
            shed_per_h: 0.1,
            restart_per_h: 0.1,
            looks_per_mm: 0.3,
            early_rime_looks_per_mm: 0.7,
            early_mm: 1.5,
            looks_per_h: 1.0,
            escape: 0.05,
            output_weight: 0.35,
            change_window_s: 240.0,
            change_noise_ua: 0.05,
            change_slope_sd: 0.8,
            change_rate_temper: 0.7,
            tell_nats: 2.0,
        }
    }
}

impl HistoryParams {
    /// Every field in its valid range; a field that is not takes its default.
    #[inline(never)]
    pub fn sanitized(self) -> Self {
        let d = HistoryParams::default();
        HistoryParams {
            enabled: self.enabled,
            period_s: within(self.period_s, 0.0, 600.0, d.period_s),
            rate_walk_per_h: within(self.rate_walk_per_h, 0.0, 100.0, d.rate_walk_per_h),
            pause_per_h: within(self.pause_per_h, 0.0, 100.0, d.pause_per_h),
            resume_per_h: within(self.resume_per_h, 0.0, 100.0, d.resume_per_h),
            resume_ice_per_h: within(self.resume_ice_per_h, 0.0, 100.0, d.resume_ice_per_h),
            shed_per_h: within(self.shed_per_h, 0.0, 100.0, d.shed_per_h),
            restart_per_h: within(self.restart_per_h, 0.0, 100.0, d.restart_per_h),
            looks_per_mm: within(self.looks_per_mm, 0.0, 100.0, d.looks_per_mm),
            early_rime_looks_per_mm: within(
                self.early_rime_looks_per_mm,
                0.0,
                100.0,
                d.early_rime_looks_per_mm,
            ),
            early_mm: within(self.early_mm, 0.0, 15.0, d.early_mm),
            looks_per_h: within(self.looks_per_h, 0.0, 3600.0, d.looks_per_h),
            escape: within(self.escape, 1e-4, 1.0, d.escape),
            output_weight: within(self.output_weight, 0.0, 1.0, d.output_weight),
            change_window_s: within(self.change_window_s, 1.0, 3600.0, d.change_window_s),
            change_noise_ua: within(self.change_noise_ua, 0.001, 100.0, d.change_noise_ua),
            change_slope_sd: within(self.change_slope_sd, 0.0, 10.0, d.change_slope_sd),
            change_rate_temper: within(self.change_rate_temper, 0.0, 10.0, d.change_rate_temper),
            tell_nats: within(self.tell_nats, 0.0, 1000.0, d.tell_nats),
        }
    }
}
