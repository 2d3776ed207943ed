//! When each message of a replay is due: the recorded pacing scaled by `--speed`.
//!
//! Offsets are measured from the first message. A sample without a timestamp comes one
//! `interval` after the previous one; a timestamp earlier than the previous one does not move
//! time backwards (the message goes out right after its predecessor). `speed` 0 means as fast as
//! possible: every offset is zero.

use std::time::Duration;

/// A `--speed` that is negative or not a number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--speed must be a number >= 0 (0 = as fast as possible), not {0}")]
pub struct SpeedError(pub f64);

/// Check a `--speed` value: finite and not negative.
pub fn check_speed(speed: f64) -> Result<f64, SpeedError> {
    if speed.is_finite() && speed >= 0.0 {
        Ok(speed)
    } else {
        Err(SpeedError(speed))
    }
}

/// A wait between two messages worth announcing: at least [`LONG_GAP`], or shortened by
/// `--max-gap`.
#[derive(Debug, Clone, PartialEq)]
pub struct Gap {
    /// The sample the wait comes before.
    pub index: usize,
    /// The wait the recording asks for (scaled by the speed).
    pub recorded: Duration,
    /// The wait the replay makes (the same, or `--max-gap`).
    pub waited: Duration,
}

/// A wait this long (after scaling) is announced before it starts.
pub const LONG_GAP: Duration = Duration::from_secs(10);

/// The due offset of every sample, from its timestamp (`None` = untimed), with every wait
/// between two messages at most `max_gap`; and the long or shortened waits.
pub fn offsets_capped(
    times_ns: &[Option<i64>],
    speed: f64,
    interval: Duration,
    max_gap: Option<Duration>,
) -> (Vec<Duration>, Vec<Gap>) {
    let recorded = offsets(times_ns, speed, interval);
    let mut out = Vec::with_capacity(recorded.len());
    let mut gaps = Vec::new();
    let mut shift = Duration::ZERO;
    for (i, at) in recorded.iter().enumerate() {
        if i > 0
            && let Some(before) = recorded.get(i - 1)
        {
            let wait = at.saturating_sub(*before);
            let waited = max_gap.map_or(wait, |m| wait.min(m));
            shift += wait - waited;
            if wait >= LONG_GAP || waited < wait {
                gaps.push(Gap {
                    index: i,
                    recorded: wait,
                    waited,
                });
            }
        }
        out.push(at.saturating_sub(shift));
    }
    (out, gaps)
}

/// The due offset of every sample, from its timestamp (`None` = untimed).
pub fn offsets(times_ns: &[Option<i64>], speed: f64, interval: Duration) -> Vec<Duration> {
    let mut offsets = Vec::with_capacity(times_ns.len());
    if speed <= 0.0 || !speed.is_finite() {
        offsets.resize(times_ns.len(), Duration::ZERO);
        return offsets;
    }
    // Recorded time elapsed since the first sample, in ns, never decreasing.
    let mut elapsed_ns: u128 = 0;
    let mut previous: Option<i64> = None;
    let step_ns = interval.as_nanos();
    for (i, time) in times_ns.iter().enumerate() {
        if i > 0 {
            match (previous, time) {
                (Some(prev), Some(now)) => {
                    let delta = i128::from(*now) - i128::from(prev);
                    elapsed_ns += u128::try_from(delta).unwrap_or(0);
                }
                _ => elapsed_ns += step_ns,
            }
        }
        if let Some(now) = time {
            // A step back in time is not replayed, but the next forward step is measured
            // from the largest time seen so far.
            previous = Some(previous.map_or(*now, |p| p.max(*now)));
        } else if let Some(p) = previous {
            previous = Some(p.saturating_add(i64::try_from(step_ns).unwrap_or(i64::MAX)));
        }
        let scaled = elapsed_ns as f64 / speed;
        offsets.push(Duration::from_nanos(scaled.min(u64::MAX as f64) as u64));
    }
    offsets
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn recorded_pacing_is_scaled() {
        let t = [Some(1000 * MS), Some(1200 * MS), Some(1600 * MS)];
        let real = offsets(&t, 1.0, Duration::from_millis(200));
        assert_eq!(
            real,
            vec![
                Duration::ZERO,
                Duration::from_millis(200),
                Duration::from_millis(600)
            ]
        );
        let fast = offsets(&t, 4.0, Duration::from_millis(200));
        assert_eq!(
            fast,
            vec![
                Duration::ZERO,
                Duration::from_millis(50),
                Duration::from_millis(150)
            ]
        );
    }

    #[test]
    fn speed_zero_is_as_fast_as_possible() {
        let t = [Some(0), Some(10 * MS), None];
        assert_eq!(
            offsets(&t, 0.0, Duration::from_secs(1)),
            vec![Duration::ZERO; 3]
        );
    }

    #[test]
    fn untimed_samples_use_the_interval_and_time_never_goes_back() {
        let t = [None, None, None];
        assert_eq!(
            offsets(&t, 1.0, Duration::from_millis(100)),
            vec![
                Duration::ZERO,
                Duration::from_millis(100),
                Duration::from_millis(200)
            ]
        );
        let back = [Some(500 * MS), Some(300 * MS), Some(700 * MS)];
        assert_eq!(
            offsets(&back, 1.0, Duration::from_millis(100)),
            vec![Duration::ZERO, Duration::ZERO, Duration::from_millis(200)]
        );
    }

    #[test]
    fn long_gaps_are_found_and_capped() {
        let s = 1_000 * MS;
        let t = [Some(0), Some(s), Some(3601 * s), Some(3602 * s)];
        let (due, gaps) = offsets_capped(&t, 1.0, Duration::from_millis(200), None);
        assert_eq!(due[3], Duration::from_secs(3602));
        assert_eq!(
            gaps,
            vec![Gap {
                index: 2,
                recorded: Duration::from_secs(3600),
                waited: Duration::from_secs(3600)
            }]
        );
        let cap = Some(Duration::from_secs(5));
        let (due, gaps) = offsets_capped(&t, 1.0, Duration::from_millis(200), cap);
        assert_eq!(
            due,
            vec![
                Duration::ZERO,
                Duration::from_secs(1),
                Duration::from_secs(6),
                Duration::from_secs(7)
            ]
        );
        assert_eq!(gaps[0].waited, Duration::from_secs(5));
        // A short gap shortened by the cap is announced too; one under both is not.
        let (_, gaps) = offsets_capped(
            &t[..2],
            1.0,
            Duration::ZERO,
            Some(Duration::from_millis(500)),
        );
        assert_eq!(gaps.len(), 1);
        let (_, gaps) = offsets_capped(&t[..2], 1.0, Duration::ZERO, None);
        assert!(gaps.is_empty());
    }

    #[test]
    fn bad_speeds_are_rejected() {
        assert!(check_speed(-1.0).is_err());
        assert!(check_speed(f64::NAN).is_err());
        assert_eq!(check_speed(0.0), Ok(0.0));
        assert_eq!(check_speed(2.5), Ok(2.5));
    }
}
