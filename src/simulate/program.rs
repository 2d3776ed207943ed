//! The robot's own program: the expected (commanded) linear speed over time.
//!
//! Owns: [`Program`], a list of steps (duration, speed), the bundled schedule
//! ([`Program::paper_steps`]) and the program file format ([`Program::parse`]): one step per
//! line, `duration_s speed_mps` (spaces, tabs or commas), `#` starts a comment. After the last
//! step the run ends.

use super::InputError;

#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// (duration s, speed m/s); durations positive.
    steps: Vec<(f64, f64)>,
}

/// Seconds each speed of the bundled program is held.
const STEP_SECONDS: f64 = 20.0;

impl Program {
    /// A program of `steps` (seconds, m/s); `Err` names the first bad step.
    pub fn from_steps(steps: Vec<(f64, f64)>) -> Result<Program, InputError> {
        if steps.is_empty() {
            return Err(InputError::NoSteps);
        }
        for (i, (d, s)) in steps.iter().enumerate() {
            if !(d.is_finite() && *d > 0.0) {
                return Err(InputError::BadDuration(i + 1, *d));
            }
            if !s.is_finite() {
                return Err(InputError::BadSpeed(i + 1, *s));
            }
        }
        Ok(Program { steps })
    }

    /// The paper's experiment: speeds between 0.015 and 0.1 m/s. The robot starts at 0.1 m/s,
    /// steps down to 0.015 m/s and back up, 20 s per speed, twice and a half (400 s), so that
    /// it meets the same speeds again later on the track ("until the expected speed reaches
    /// 0.1 again at around 250 seconds").
    pub fn paper_steps() -> Program {
        let cycle = [0.1, 0.07, 0.05, 0.03, 0.015, 0.03, 0.05, 0.07];
        let steps = cycle
            .iter()
            .cycle()
            .take(20)
            .map(|&s| (STEP_SECONDS, s))
            .collect();
        Program { steps }
    }

    /// Read the file format described at the top of this module.
    pub fn parse(text: &str) -> Result<Program, InputError> {
        let mut steps = Vec::new();
        for (n, cols) in super::data_rows(text) {
            let [d, s] = cols.as_slice() else {
                return Err(InputError::Columns {
                    line: n,
                    expected: "duration_s speed_mps",
                    found: cols.len(),
                });
            };
            let num = |c: &str| {
                c.parse::<f64>()
                    .map_err(|_| InputError::NotANumber(n, c.to_string()))
            };
            steps.push((num(d)?, num(s)?));
        }
        Program::from_steps(steps).map_err(|e| InputError::ProgramFile(Box::new(e)))
    }

    /// Total duration (s).
    pub fn duration(&self) -> f64 {
        self.steps.iter().map(|s| s.0).sum()
    }

    /// The expected speed at time `t` (s since the start); the last step's after the end.
    pub fn speed_at(&self, t: f64) -> f64 {
        let mut end = 0.0;
        for (d, s) in &self.steps {
            end += d;
            if t < end {
                return *s;
            }
        }
        self.steps.last().map_or(0.0, |s| s.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_steps_stay_within_the_papers_range() {
        let p = Program::paper_steps();
        assert_eq!(p.duration(), 400.0);
        assert_eq!(p.speed_at(0.0), 0.1);
        assert_eq!(p.speed_at(85.0), 0.015);
        assert_eq!(p.speed_at(165.0), 0.1);
        for i in 0..800 {
            let s = p.speed_at(i as f64 * 0.5);
            assert!((0.015..=0.1).contains(&s));
        }
    }

    #[test]
    fn parse_and_errors() {
        let p = Program::parse("# steps\n10 0.05\n5, 0.1\n").unwrap();
        assert_eq!(p.duration(), 15.0);
        assert_eq!(p.speed_at(9.99), 0.05);
        assert_eq!(p.speed_at(10.0), 0.1);
        assert_eq!(p.speed_at(99.0), 0.1);
        assert!(
            Program::parse("10\n")
                .unwrap_err()
                .to_string()
                .contains("line 1")
        );
        assert!(
            Program::parse("1 1\n0 1\n")
                .unwrap_err()
                .to_string()
                .contains("step 2")
        );
        assert!(
            Program::parse("a 1\n")
                .unwrap_err()
                .to_string()
                .contains("line 1")
        );
        assert!(
            Program::parse("")
                .unwrap_err()
                .to_string()
                .contains("no steps")
        );
    }
}
