//! Finite numbers from a command line, for clap value parsers: what
//! `foisctl` and `fois-gateway` accept for durations, rates and ranges. NaN,
//! ±∞ and text are refused with words that say why (clap prints them and
//! exits with code 2).

fn number(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(format!("`{s}` is not a finite number")),
        Err(_) => Err(format!("`{s}` is not a number")),
    }
}

/// A finite number > 0.
pub fn positive(s: &str) -> Result<f64, String> {
    number(s).and_then(|x| {
        if x > 0.0 {
            Ok(x)
        } else {
            Err(format!("must be > 0, got {x}"))
        }
    })
}

/// A finite number ≥ 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    number(s).and_then(|x| {
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(format!("must be >= 0, got {x}"))
        }
    })
}

/// A clap value parser for a finite number in `lo..=hi`.
pub fn f64_in(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    move |s| {
        number(s).and_then(|x| {
            if (lo..=hi).contains(&x) {
                Ok(x)
            } else {
                Err(format!("must be within {lo}..={hi}, got {x}"))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_and_non_finite_values_are_refused() {
        assert_eq!(positive("0.5"), Ok(0.5));
        for bad in ["0", "-1", "nan", "inf", "x", ""] {
            assert!(positive(bad).is_err(), "{bad}");
        }
        assert_eq!(non_negative("0"), Ok(0.0));
        assert_eq!(
            non_negative("-0.001"),
            Err("must be >= 0, got -0.001".into())
        );
        let t = f64_in(-60.0, 80.0);
        assert_eq!(t("-60"), Ok(-60.0));
        assert_eq!(t("80.01"), Err("must be within -60..=80, got 80.01".into()));
        assert_eq!(t("NaN"), Err("`NaN` is not a finite number".into()));
    }
}
