//! One duration syntax for every command's time flag: a bare number of seconds (`60`,
//! `0.5`) or a number with a unit: `ms`, `s`, `m` (minutes), `h` (`500ms`, `90s`, `10m`,
//! `1.5h`).

/// Seconds in `text` (`90`, `90s`, `500ms`, `10m`, `1.5h`), finite and within a week.
fn seconds(text: &str) -> Result<f64, String> {
    let t = text.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix('m') {
        (n, 60.0)
    } else if let Some(n) = t.strip_suffix('h') {
        (n, 3600.0)
    } else {
        (t, 1.0)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a duration (e.g. 60, 60s, 500ms, 10m, 1h)"))?;
    let s = v * scale;
    if !(0.0..=7.0 * 86400.0).contains(&s) {
        return Err(format!(
            "`{text}`: a duration must be at least 0 and at most a week"
        ));
    }
    Ok(s)
}

/// A duration in seconds that must be positive (run times, timeouts, periods).
pub fn parse(text: &str) -> Result<f64, String> {
    let s = seconds(text)?;
    if s == 0.0 {
        return Err(format!("`{text}`: the duration must be greater than 0"));
    }
    Ok(s)
}

/// A duration in seconds where 0 has a meaning (e.g. "time-optimal", "none").
pub fn parse_or_zero(text: &str) -> Result<f64, String> {
    seconds(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_form_gives_seconds() {
        for (text, s) in [
            ("60", 60.0),
            ("60s", 60.0),
            ("0.5", 0.5),
            ("500ms", 0.5),
            ("10m", 600.0),
            ("1h", 3600.0),
            ("1.5h", 5400.0),
            (" 2 s ", 2.0),
        ] {
            assert_eq!(parse(text), Ok(s), "{text}");
        }
    }

    #[test]
    fn bad_durations_are_refused_with_the_text() {
        for text in ["", "abc", "10x", "-1", "NaN", "inf", "8d", "200h"] {
            let e = parse(text).expect_err(text);
            assert!(e.contains(text), "{text}: {e}");
        }
        assert!(parse("0").is_err());
        assert_eq!(parse_or_zero("0"), Ok(0.0));
    }
}
