//! The ranges of the numbers fdd takes on its command line, each with its unit and the reason
//! for its bounds, and their parsers: a value out of range (a count of a billion particles, a
//! negative duration, NaN) is refused with a message naming the flag, instead of a panic, an
//! abort on a huge allocation or a run that never ends.

/// A whole-number argument: `min..=max` of `unit`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CountArg {
    /// The flag, as the user writes it (`--particles`).
    pub flag: &'static str,
    pub min: u64,
    pub max: u64,
    /// What it counts (`particles`); may be empty.
    pub unit: &'static str,
    /// Why the bounds are what they are.
    pub why: &'static str,
}

impl CountArg {
    /// `n` when it lies in the range, else the message saying the range and why.
    pub fn check(&self, n: u64) -> Result<u64, String> {
        if (self.min..=self.max).contains(&n) {
            Ok(n)
        } else {
            Err(self.range_message(&n.to_string()))
        }
    }

    /// Parses a command-line value (a leading minus is read, and refused as out of range). The
    /// message says the range and why; clap puts the flag and the value before it.
    pub fn parse(&self, s: &str) -> Result<u64, String> {
        let t = s.trim().replace('_', "");
        match t.parse::<i128>() {
            Ok(n) if n >= 0 && n <= i128::from(u64::MAX) && self.check(n as u64).is_ok() => {
                Ok(n as u64)
            }
            Ok(_) => Err(self.range()),
            Err(_) => Err(format!("not a whole number; {}", self.range())),
        }
    }

    /// [`CountArg::parse`] into a `usize` (the range fits one on every platform fdd builds
    /// for; a larger value is refused the same way).
    pub fn parse_usize(&self, s: &str) -> Result<usize, String> {
        let n = self.parse(s)?;
        usize::try_from(n).map_err(|_| self.range())
    }

    fn range(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!(
            "must be from {} to {}{unit} ({})",
            self.min, self.max, self.why
        )
    }

    fn range_message(&self, shown: &str) -> String {
        format!("{} {shown}: {}", self.flag, self.range())
    }
}

/// A number argument in `[min, max]` (`(min, max]` when `min_exclusive`) of `unit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeArg {
    /// The flag, as the user writes it (`--block-s`).
    pub flag: &'static str,
    pub min: f64,
    pub min_exclusive: bool,
    pub max: f64,
    /// The unit (`s`); may be empty.
    pub unit: &'static str,
    /// Why the bounds are what they are.
    pub why: &'static str,
}

impl RangeArg {
    /// `v` when it lies in the range (NaN never does), else the message saying the range and
    /// why.
    pub fn check(&self, v: f64) -> Result<f64, String> {
        let above_min = if self.min_exclusive {
            v > self.min
        } else {
            v >= self.min
        };
        if above_min && v <= self.max {
            Ok(v)
        } else {
            Err(format!("{} {v:?}: {}", self.flag, self.range()))
        }
    }

    /// Parses a command-line value (`-1`, `nan` and `1e300` are read, then refused as out of
    /// range). The message says the range and why; clap puts the flag and the value before it.
    pub fn parse(&self, s: &str) -> Result<f64, String> {
        match s.trim().parse::<f64>() {
            Ok(v) if self.check(v).is_ok() => Ok(v),
            Ok(_) => Err(self.range()),
            Err(_) => Err(format!("not a number; {}", self.range())),
        }
    }

    fn range(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        let lower = if self.min_exclusive {
            format!("above {:?}", self.min)
        } else {
            format!("from {:?}", self.min)
        };
        format!("must be {lower} to {:?}{unit} ({})", self.max, self.why)
    }
}

/// `fdd reproduce table2 --samples`.
pub const TABLE2_SAMPLES: CountArg = CountArg {
    flag: "--samples",
    min: 1,
    max: 1_000_000_000,
    unit: "samples",
    why:
        "1 ms samples: 10^9 is 11.6 days of throttle time, and already most of an hour of run time",
};

/// `fdd reproduce table2 --particles`.
pub const TABLE2_PARTICLES: CountArg = CountArg {
    flag: "--particles",
    min: 2,
    max: 1_000_000,
    unit: "particles",
    why: "a bootstrap filter needs two; each particle is about 64 bytes of state and costs about \
          35 ns per sample, so 10^6 particles take 64 MB and a day over the default 2,000,000 \
          samples",
};

/// `--seed` of the reproductions: any 64-bit seed.
pub const SEED: CountArg = CountArg {
    flag: "--seed",
    min: 0,
    max: u64::MAX,
    unit: "",
    why: "a 64-bit seed",
};

/// `fdd reproduce table2 --wattmeter-std`.
pub const TABLE2_WATTMETER_STD: RangeArg = RangeArg {
    flag: "--wattmeter-std",
    min: 0.0,
    min_exclusive: true,
    max: 100.0,
    unit: "A^2",
    why: "the standard deviation of the wattmeter noise; i^2 itself is 0..1.5 A^2, the paper's \
          noise 1 A^2",
};

/// `fdd reproduce intake --duration`.
pub const INTAKE_DURATION: RangeArg = RangeArg {
    flag: "--duration",
    min: 1.0,
    min_exclusive: false,
    max: 3600.0,
    unit: "s",
    why: "the drive's frames are all kept in memory, some 30 kB per second of drive: an hour is \
          about 100 MB",
};

/// `fdd reproduce intake --egr`.
pub const INTAKE_EGR: RangeArg = RangeArg {
    flag: "--egr",
    min: 0.0,
    min_exclusive: false,
    max: 1.0,
    unit: "",
    why: "an EGR valve position, 0 closed to 1 open",
};

/// `fdd calibrate --false-alarms-per-hour`.
pub const CALIBRATE_RATE: RangeArg = RangeArg {
    flag: "--false-alarms-per-hour",
    min: 0.0,
    min_exclusive: true,
    max: 3600.0,
    unit: "per hour",
    why: "a test allowed to alarm more than once a second is not calibrated for false alarms",
};

/// `fdd calibrate --block-s`.
pub const CALIBRATE_BLOCK: RangeArg = RangeArg {
    flag: "--block-s",
    min: 0.1,
    min_exclusive: false,
    max: 86_400.0,
    unit: "s",
    why: "a block must hold many monitor steps (1 ms throttle samples, intake segments of up to \
          60 ms), and the logs must hold at least 20 blocks",
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_refuse_negative_huge_and_non_numbers_naming_the_flag() {
        assert_eq!(TABLE2_PARTICLES.parse("2000"), Ok(2000));
        assert_eq!(TABLE2_PARTICLES.parse("1_000"), Ok(1000));
        for bad in [
            "-1",
            "1",
            "24000000000000",
            "99999999999999999999999",
            "x",
            "1.5",
        ] {
            let e = TABLE2_PARTICLES.parse(bad).unwrap_err();
            assert!(e.contains("from 2 to 1000000 particles"), "{e}");
        }
        assert_eq!(SEED.parse(&u64::MAX.to_string()), Ok(u64::MAX));
        assert!(SEED.parse("-1").is_err());
        let e = TABLE2_PARTICLES.check(0).unwrap_err();
        assert!(e.starts_with("--particles 0: must be from 2"), "{e}");
    }

    #[test]
    fn ranges_refuse_nan_negative_and_huge_naming_the_flag_and_unit() {
        assert_eq!(CALIBRATE_BLOCK.parse("10"), Ok(10.0));
        for bad in ["-1", "nan", "NaN", "1e300", "inf", "0", "x"] {
            let e = CALIBRATE_BLOCK.parse(bad).unwrap_err();
            assert!(e.contains("from 0.1 to 86400.0 s"), "{e}");
        }
        let e = TABLE2_WATTMETER_STD.parse("0").unwrap_err();
        assert!(e.contains("above 0.0") && e.contains("A^2"), "{e}");
        let e = CALIBRATE_RATE.check(1e300).unwrap_err();
        assert!(
            e.starts_with("--false-alarms-per-hour 1e300:"),
            "readable, not 301 digits: {e}"
        );
    }
}
