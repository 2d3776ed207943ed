//! Time in a spec: the base time (`--base-time`, a case's `baseTime`) and the units of time
//! literals (`5 s`), in femtoseconds.
//!
//! Owns: [`parse_base_parts`] (the base time as count and unit) and `unit_factor`; the
//! lowering converts a literal `n unit` to `n * unit / base` (`lower`'s `ExprKind::Int`).

/// The length of a time unit in femtoseconds.
pub(crate) fn unit_factor(unit: &str) -> Option<i128> {
    Some(match unit {
        "fs" => 1,
        "ps" => 1_000,
        "ns" => 1_000_000,
        "us" | "µs" => 1_000_000_000,
        "ms" => 1_000_000_000_000,
        "s" => 1_000_000_000_000_000,
        "min" => 60_000_000_000_000_000,
        "h" => 3_600_000_000_000_000_000,
        "d" => 86_400_000_000_000_000_000,
        _ => return None,
    })
}

/// Why a base time is not one: a bad number, an unknown unit, or not positive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BaseTimeError(pub String);

impl std::fmt::Display for BaseTimeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BaseTimeError {}

impl From<String> for BaseTimeError {
    fn from(message: String) -> Self {
        BaseTimeError(message)
    }
}

/// Parse a base time in TeSSLa's form (`1 ns`, `33333 µs`, `1ms`) into femtoseconds.
pub fn parse_base_time(s: &str) -> Result<i128, BaseTimeError> {
    parse_base_parts(s).map(|(n, unit)| n * unit)
}

/// A base time as (count, unit in femtoseconds): `33333 µs` -> (33333, 10^9).
pub fn parse_base_parts(s: &str) -> Result<(i128, i128), BaseTimeError> {
    let s = s.trim();
    let split = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let n: i128 = if num.is_empty() {
        1
    } else {
        num.parse()
            .map_err(|_| format!("bad number in base time `{s}`"))?
    };
    let f = unit_factor(unit.trim()).ok_or_else(|| {
        format!("unknown unit in base time `{s}`: use fs, ps, ns, us, µs, ms, s, min, h or d")
    })?;
    if n <= 0 {
        return Err(BaseTimeError(format!("base time `{s}` must be positive")));
    }
    Ok((n, f))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base_times_parse_in_tesslas_forms() {
        assert_eq!(parse_base_time("1 ns"), Ok(1_000_000));
        assert_eq!(parse_base_time("1ms"), Ok(1_000_000_000_000));
        assert_eq!(parse_base_time("33333 µs"), Ok(33_333_000_000_000));
        assert!(parse_base_time("5 parsecs").is_err());
        assert!(parse_base_time("0 s").is_err());
    }
}
