//! Exact decimal arithmetic for the time column: a time written `100.005243248909` (s) becomes
//! 100,005,243,249 ns exactly, with no binary floating point in between. A `f64` has 15-17
//! significant digits, so a Unix time in nanoseconds (19 digits) or in seconds with nine
//! decimals would lose up to a few hundred ns through one; the digits are scaled instead.

/// Why a field is not a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DecimalError {
    /// Not a decimal number (`abc`, `1,5`, an empty field).
    NotANumber,
    /// `NaN`, `inf` or `infinity` (any case, with a sign or not).
    NotFinite,
    /// A number whose value scaled to ns does not fit in 127 bits (beyond 10^38 ns, i.e. about
    /// 10^21 years).
    OutOfRange,
}

/// Largest exponent accepted (`1e9999` is refused as out of range, not parsed digit by digit).
const MAX_EXPONENT: i64 = 10_000;

/// The value of the decimal `text` (`[+-]digits[.digits][(e|E)[+-]digits]`, at least one
/// digit in the mantissa; surrounding spaces are the caller's to trim) times `10^exp10`,
/// rounded to the nearest integer, ties away from zero.
pub(crate) fn scaled_integer(text: &str, exp10: i32) -> Result<i128, DecimalError> {
    let lower = text.to_ascii_lowercase();
    let unsigned = lower
        .strip_prefix('-')
        .or_else(|| lower.strip_prefix('+'))
        .unwrap_or(&lower);
    if matches!(unsigned, "nan" | "inf" | "infinity") {
        return Err(DecimalError::NotFinite);
    }
    let bytes = text.as_bytes();
    let mut i = 0;
    let negative = match bytes.first() {
        Some(b'-') => {
            i = 1;
            true
        }
        Some(b'+') => {
            i = 1;
            false
        }
        _ => false,
    };
    // Mantissa digits without leading zeros; `frac` counts the digits after the point.
    let mut digits: Vec<u8> = Vec::new();
    let mut seen_digit = false;
    let mut frac: i64 = 0;
    let mut in_frac = false;
    while let Some(&b) = bytes.get(i) {
        match b {
            b'0'..=b'9' => {
                seen_digit = true;
                if !(digits.is_empty() && b == b'0') {
                    digits.push(b - b'0');
                }
                if in_frac {
                    frac += 1;
                }
            }
            b'.' if !in_frac => in_frac = true,
            _ => break,
        }
        i += 1;
    }
    if !seen_digit {
        return Err(DecimalError::NotANumber);
    }
    let mut exponent: i64 = 0;
    if let Some(b'e' | b'E') = bytes.get(i) {
        i += 1;
        let exp_negative = match bytes.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        while let Some(b'0'..=b'9') = bytes.get(i) {
            exponent = (exponent * 10 + i64::from(bytes[i] - b'0')).min(MAX_EXPONENT + 1);
            i += 1;
        }
        if i == start {
            return Err(DecimalError::NotANumber);
        }
        if exp_negative {
            exponent = -exponent;
        }
    }
    if i != bytes.len() {
        return Err(DecimalError::NotANumber);
    }
    if digits.is_empty() {
        return Ok(0);
    }
    if exponent.abs() > MAX_EXPONENT {
        return if exponent < 0 {
            Ok(0)
        } else {
            Err(DecimalError::OutOfRange)
        };
    }
    // value = digits x 10^shift
    let shift = exponent - frac + i64::from(exp10);
    let len = digits.len() as i64;
    let (kept, round_up) = if shift >= 0 {
        (&digits[..], false)
    } else {
        // Keep the digits left of the point after scaling; round on the first one dropped.
        let keep = len + shift;
        if keep < 0 {
            return Ok(0);
        }
        let keep = keep as usize;
        (&digits[..keep], digits.get(keep).is_some_and(|&d| d >= 5))
    };
    if kept.len() > 38 {
        return Err(DecimalError::OutOfRange);
    }
    let mut value: i128 = 0;
    for &d in kept {
        value = value * 10 + i128::from(d);
    }
    if round_up {
        value += 1;
    }
    if shift > 0 {
        let pow = u32::try_from(shift).map_err(|_| DecimalError::OutOfRange)?;
        value = 10i128
            .checked_pow(pow)
            .and_then(|p| value.checked_mul(p))
            .ok_or(DecimalError::OutOfRange)?;
    }
    Ok(if negative { -value } else { value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_to_ns_exactly() {
        assert_eq!(scaled_integer("100.005243248909", 9), Ok(100_005_243_249));
        assert_eq!(scaled_integer("0.0125056", 9), Ok(12_505_600));
        assert_eq!(scaled_integer("1", 9), Ok(1_000_000_000));
        assert_eq!(scaled_integer("1.", 9), Ok(1_000_000_000));
        assert_eq!(scaled_integer(".5", 9), Ok(500_000_000));
        assert_eq!(scaled_integer("-2.5e-3", 9), Ok(-2_500_000));
        assert_eq!(scaled_integer("1.5E3", 6), Ok(1_500_000_000));
        assert_eq!(scaled_integer("+7", 0), Ok(7));
        assert_eq!(scaled_integer("000", 9), Ok(0));
        // A Unix time in ns keeps every digit (a f64 would round it to 256 ns).
        assert_eq!(
            scaled_integer("1733463600123456789", 0),
            Ok(1_733_463_600_123_456_789)
        );
    }

    #[test]
    fn rounds_half_away_from_zero() {
        assert_eq!(scaled_integer("0.0000000005", 9), Ok(1));
        assert_eq!(scaled_integer("0.00000000049999", 9), Ok(0));
        assert_eq!(scaled_integer("-0.0000000005", 9), Ok(-1));
        assert_eq!(scaled_integer("1.4999", 0), Ok(1));
        assert_eq!(scaled_integer("1e-9999", 9), Ok(0));
    }

    #[test]
    fn refuses_what_is_not_a_finite_decimal() {
        for bad in [
            "", "-", ".", "e5", "1e", "1e+", "1.2.3", "1,5", "abc", "1 2", "0x10", "--1",
        ] {
            assert_eq!(
                scaled_integer(bad, 9),
                Err(DecimalError::NotANumber),
                "{bad}"
            );
        }
        for bad in ["NaN", "nan", "-inf", "+Infinity", "INF"] {
            assert_eq!(
                scaled_integer(bad, 9),
                Err(DecimalError::NotFinite),
                "{bad}"
            );
        }
        for bad in [
            "1e30",
            "1e99999999999999999999",
            "123456789012345678901234567890123456789",
        ] {
            assert_eq!(
                scaled_integer(bad, 9),
                Err(DecimalError::OutOfRange),
                "{bad}"
            );
        }
    }
}
