//! A fast path for the small flat JSON objects of fdd's logs (`{"voltage_v":1.2345}`, the
//! truth messages): one pass over the bytes, eight at a time, no serde machinery, and numbers
//! converted exactly as serde_json converts them.
//!
//! [`FlatObject`] accepts only an object whose members are all scalars: numbers, `null`,
//! booleans and strings without escapes, with keys and strings of printable ASCII (no escape,
//! no control character, no byte >= 0x80) and keys without `.`, whitespace allowed where JSON
//! allows it. Everything it accepts is valid JSON; anything else (nesting, escapes, non-ASCII
//! text, a dotted key, invalid JSON) is [`NotFlat`], and the caller then uses the general
//! serde_json path, which gives the result or the error it always gave.
//! [`FlatNumber::to_f64`] (and [`number_f64`]) likewise return `None` for what they do not
//! reproduce exactly (a significand beyond `u64`, an exponent beyond `i32`, an out-of-range
//! number), and the caller falls back.
//!
//! # Numbers: why not `str::parse::<f64>`
//!
//! fdd builds serde_json without its `float_roundtrip` feature, so serde_json reads a decimal
//! number as `significand as f64` multiplied or divided by a power of ten, which is not always
//! the correctly rounded value that `str::parse` gives (17-digit numbers written by `ryu`, as
//! fdd writes them, differ in the last bit now and then). [`FlatNumber::to_f64`] repeats
//! serde_json's arithmetic step by step (`serde_json::de::Deserializer::f64_from_parts` of
//! serde_json 1.x), so the fast path is bit-identical to the general one. The property tests in
//! `monitor/src/log/field.rs` compare the two on generated numbers: should a dependency ever
//! turn on `float_roundtrip`, they fail.

/// The text is not a flat object (or not valid JSON): use the general parser.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotFlat;

/// A member value of a [`FlatObject`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FlatValue<'a> {
    /// A number (valid JSON number syntax).
    Number(FlatNumber<'a>),
    /// `null`.
    Null,
    /// `true` or `false`.
    Bool(bool),
    /// A string without escapes: its content, printable ASCII.
    Str(&'a [u8]),
}

/// A key known to be plain (printable ASCII without `"`, `\` or `.`), for
/// [`FlatObject::next_key_is`]; checked when the constant is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlainKey {
    key: &'static [u8],
    /// `key":` as two little-endian words (zero past its end) and the masks of its bytes, when
    /// it has at most 16 bytes: then compared with two word loads.
    pattern: [u64; 2],
    mask: [u64; 2],
}

impl PlainKey {
    /// `key`, which must be plain (a panic otherwise: at compile time in a constant).
    pub const fn new(key: &'static [u8]) -> Self {
        let mut pattern = [0u64; 2];
        let mut mask = [0u64; 2];
        let n = key.len() + 2;
        let mut i = 0;
        while i < n {
            let c = if i < key.len() {
                key[i]
            } else if i == key.len() {
                b'"'
            } else {
                b':'
            };
            if i < key.len() {
                assert!(
                    c >= 0x20 && c < 0x80 && c != b'"' && c != b'\\' && c != b'.',
                    "not a plain key"
                );
            }
            if i < 16 {
                pattern[i / 8] |= (c as u64) << (8 * (i % 8));
                mask[i / 8] |= 0xFF << (8 * (i % 8));
            }
            i += 1;
        }
        PlainKey { key, pattern, mask }
    }

    /// The key.
    pub const fn bytes(self) -> &'static [u8] {
        self.key
    }

    /// Whether `b[i..]` starts with `key":`.
    #[inline(always)]
    fn starts(&self, b: &[u8], i: usize) -> bool {
        if self.key.len() + 2 > 16 {
            let k = self.key.len();
            return b.get(i..i + k) == Some(self.key) && b.get(i + k..i + k + 2) == Some(b"\":");
        }
        // Bytes past the end of `b` read as zeros, which no pattern byte is.
        ((word_at(b, i) ^ self.pattern[0]) & self.mask[0])
            | ((word_at(b, i + 8) ^ self.pattern[1]) & self.mask[1])
            == 0
    }
}

/// A number of a [`FlatObject`]: its text and its parts, read in the same pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlatNumber<'a> {
    text: &'a [u8],
    /// The integer and fraction digits as one integer (when `short`).
    significand: u64,
    /// Index of the `e` / `E` in `text`, or its length without an exponent.
    exp_at: u32,
    frac_digits: u8,
    negative: bool,
    /// At most 19 integer and fraction digits: `significand` holds them (else serde_json's
    /// digit-by-digit rules apply).
    short: bool,
}

/// Reads the members of a flat object in order (see the [module documentation](self)): a key
/// with [`next_key`](Self::next_key), then its value with [`value`](Self::value), until
/// `next_key` says the object is closed.
///
/// ```
/// use fdd_monitor::log::flat_json::{FlatObject, FlatValue};
/// let mut obj = FlatObject::new(br#"{"voltage_v":1.25,"ok":true}"#).unwrap();
/// assert_eq!(obj.next_key(), Ok(Some(&b"voltage_v"[..])));
/// assert!(matches!(obj.value(), Ok(FlatValue::Number(n)) if n.to_f64() == Some(1.25)));
/// assert_eq!(obj.next_member(), Ok(Some((&b"ok"[..], FlatValue::Bool(true)))));
/// assert_eq!(obj.next_key(), Ok(None));
/// ```
#[derive(Debug, Clone)]
pub struct FlatObject<'a> {
    b: &'a [u8],
    /// At the first key's `"`, at a value, or at the `,` or `}` after a value (whitespace
    /// skipped).
    i: usize,
    first: bool,
}

impl<'a> FlatObject<'a> {
    /// Starts reading `json`, which must open an object.
    #[inline]
    pub fn new(json: &'a [u8]) -> Result<Self, NotFlat> {
        let i = skip_ws(json, 0);
        if json.get(i) != Some(&b'{') {
            return Err(NotFlat);
        }
        Ok(Self {
            b: json,
            i: skip_ws(json, i + 1),
            first: true,
        })
    }

    /// The next key, positioned at its value; `Ok(None)` when the object is closed and nothing
    /// but whitespace follows (then do not call again); `Err(NotFlat)` as soon as the text is
    /// anything else, and what was read before must then be discarded.
    #[inline(always)]
    pub fn next_key(&mut self) -> Result<Option<&'a [u8]>, NotFlat> {
        let b = self.b;
        let mut i = self.i;
        match b.get(i) {
            Some(b'"') if self.first => {}
            Some(b',') if !self.first => i = skip_ws(b, i + 1),
            Some(b'}') => {
                return if skip_ws(b, i + 1) == b.len() {
                    Ok(None)
                } else {
                    Err(NotFlat)
                };
            }
            _ => return Err(NotFlat),
        }
        self.first = false;
        if b.get(i) != Some(&b'"') {
            return Err(NotFlat);
        }
        let key_end = plain_string_end::<true>(b, i + 1).ok_or(NotFlat)?;
        let key = &b[i + 1..key_end];
        i = skip_ws(b, key_end + 1);
        if b.get(i) != Some(&b':') {
            return Err(NotFlat);
        }
        self.i = skip_ws(b, i + 1);
        Ok(Some(key))
    }

    /// The value after the key [`next_key`](Self::next_key) returned.
    #[inline(always)]
    pub fn value(&mut self) -> Result<FlatValue<'a>, NotFlat> {
        let b = self.b;
        let i = self.i;
        let (value, end) = match b.get(i) {
            Some(b'-' | b'0'..=b'9') => {
                let n = scan_number(b, i).ok_or(NotFlat)?;
                (FlatValue::Number(n), i + n.text.len())
            }
            Some(b'"') => {
                let end = plain_string_end::<false>(b, i + 1).ok_or(NotFlat)?;
                (FlatValue::Str(&b[i + 1..end]), end + 1)
            }
            Some(b'n') if b.get(i..i + 4) == Some(b"null") => (FlatValue::Null, i + 4),
            Some(b't') if b.get(i..i + 4) == Some(b"true") => (FlatValue::Bool(true), i + 4),
            Some(b'f') if b.get(i..i + 5) == Some(b"false") => (FlatValue::Bool(false), i + 5),
            _ => return Err(NotFlat),
        };
        self.i = skip_ws(b, end);
        Ok(value)
    }

    /// Whether the next key is `key` written `"key":` (as serde_json writes it), and then
    /// positioned at its value as after [`next_key`](Self::next_key); `false` (nothing read)
    /// for any other key or spelling, the end of the object or anything else (then use
    /// `next_key`). Quicker than `next_key` for a key the caller expects: a known plain key is
    /// only compared.
    #[inline(always)]
    pub fn next_key_is(&mut self, key: PlainKey) -> bool {
        let b = self.b;
        let mut i = self.i;
        match b.get(i) {
            Some(b'"') if self.first => {}
            Some(b',') if !self.first => i = skip_ws(b, i + 1),
            _ => return false,
        }
        // Compact `"key":` only (with whitespace around the colon: `next_key`).
        if b.get(i) != Some(&b'"') || !key.starts(b, i + 1) {
            return false;
        }
        self.first = false;
        self.i = skip_ws(b, i + 3 + key.key.len());
        true
    }

    /// Checks the value after a key and moves past it, without converting a number.
    #[inline(always)]
    pub fn skip_value(&mut self) -> Result<(), NotFlat> {
        let b = self.b;
        let i = self.i;
        let end = match b.get(i) {
            Some(b'-' | b'0'..=b'9') => number_end(b, i).ok_or(NotFlat)?,
            Some(b'"') => plain_string_end::<false>(b, i + 1).ok_or(NotFlat)? + 1,
            Some(b'n') if b.get(i..i + 4) == Some(b"null") => i + 4,
            Some(b't') if b.get(i..i + 4) == Some(b"true") => i + 4,
            Some(b'f') if b.get(i..i + 5) == Some(b"false") => i + 5,
            _ => return Err(NotFlat),
        };
        self.i = skip_ws(b, end);
        Ok(())
    }

    /// [`next_key`](Self::next_key) and [`value`](Self::value) together.
    #[inline]
    pub fn next_member(&mut self) -> Result<Option<(&'a [u8], FlatValue<'a>)>, NotFlat> {
        match self.next_key()? {
            Some(key) => Ok(Some((key, self.value()?))),
            None => Ok(None),
        }
    }
}

/// The number `json` holds when it is exactly `{"<key>":<number>}`, the shape of every signal
/// message fdd writes, with a plain key (as in [`FlatObject`]); `None` for anything else, or a
/// number [`FlatNumber::to_f64`] leaves to serde_json. Quicker than a [`FlatObject`] for that
/// one shape.
#[inline]
pub fn single_number_member(json: &[u8], key: &[u8]) -> Option<f64> {
    let (n, k) = (json.len(), key.len());
    // `{"`, the key, `":`, at least one digit, `}`.
    if n < k + 6
        || json[0] != b'{'
        || json[1] != b'"'
        || json[k + 2] != b'"'
        || json[k + 3] != b':'
        || json[n - 1] != b'}'
        || &json[2..k + 2] != key
        || plain_string_end::<true>(json, 2) != Some(k + 2)
    {
        return None;
    }
    let number = scan_number(json, k + 4)?;
    if k + 4 + number.text.len() != n - 1 {
        return None;
    }
    number.to_f64()
}

/// Calls `member(key, value)` for each member of the flat object `json`; `false` (possibly
/// after some calls) when it is not one. See [`FlatObject`].
pub fn scan_flat_object<'a>(
    json: &'a [u8],
    mut member: impl FnMut(&'a [u8], FlatValue<'a>),
) -> bool {
    let Ok(mut obj) = FlatObject::new(json) else {
        return false;
    };
    loop {
        match obj.next_member() {
            Ok(Some((k, v))) => member(k, v),
            Ok(None) => return true,
            Err(NotFlat) => return false,
        }
    }
}

/// Whitespace as JSON (and serde_json) defines it.
#[inline(always)]
fn skip_ws(b: &[u8], mut i: usize) -> usize {
    while let Some(&c) = b.get(i) {
        if c > b' ' || !matches!(c, b' ' | b'\n' | b'\t' | b'\r') {
            break;
        }
        i += 1;
    }
    i
}

// Eight bytes at a time ("SWAR"): a message is read as little-endian `u64` words, so that byte
// `i` is the lowest of its word, and each test below sets the high bit of the bytes it flags.
// Only the lowest flagged byte of a word is exact (a borrow or carry may flag bytes above it),
// which is all a scan for the end of a run needs.
const ONES: u64 = 0x0101_0101_0101_0101;
const HIGHS: u64 = 0x8080_8080_8080_8080;

/// The bytes `i..i + 8` of `b` as a little-endian word, with zero bytes past the end.
#[inline(always)]
fn word_at(b: &[u8], i: usize) -> u64 {
    let n = b.len();
    if n >= 8 {
        let last = n - 8;
        if i <= last {
            return u64::from_le_bytes(b[i..i + 8].try_into().unwrap_or([0; 8]));
        }
        if i < n {
            // The last eight bytes, shifted down to start at `i`.
            let w = u64::from_le_bytes(b[last..].try_into().unwrap_or([0; 8]));
            return w >> (8 * (i - last));
        }
        return 0;
    }
    short_word_at(b, i)
}

/// [`word_at`] in a text shorter than eight bytes.
#[cold]
fn short_word_at(b: &[u8], i: usize) -> u64 {
    let mut w = [0u8; 8];
    for (d, s) in w.iter_mut().zip(b.iter().skip(i)) {
        *d = *s;
    }
    u64::from_le_bytes(w)
}

/// Bytes equal to `c`.
#[inline(always)]
fn eq_bytes(x: u64, c: u8) -> u64 {
    let v = x ^ (ONES * u64::from(c));
    v.wrapping_sub(ONES) & !v & HIGHS
}

/// Bytes that end a plain string: `"`, `\`, a control character (< 0x20), or non-ASCII.
#[inline(always)]
fn string_stops(x: u64) -> u64 {
    let control = x.wrapping_sub(ONES * 0x20) & !x & HIGHS;
    eq_bytes(x, b'"') | eq_bytes(x, b'\\') | control | (x & HIGHS)
}

/// Bytes that are not ASCII digits.
#[inline(always)]
fn non_digits(x: u64) -> u64 {
    const HIGH_NIBBLES: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    const THREES: u64 = 0x3030_3030_3030_3030;
    // Not 0x3_, or not 0x30..=0x39 (adding 6 carries 0x3A..=0x3F into 0x4_).
    let w = ((x & HIGH_NIBBLES) ^ THREES) | ((x.wrapping_add(ONES * 6) & HIGH_NIBBLES) ^ THREES);
    // Non-zero bytes of `w`, exactly (no carry crosses a byte).
    (((w & !HIGHS).wrapping_add(!HIGHS)) | w) & HIGHS
}

/// Index of the lowest flagged byte of a non-zero mask.
#[inline(always)]
fn first_flagged(mask: u64) -> usize {
    (mask.trailing_zeros() / 8) as usize
}

/// The index of the closing quote of a string whose content starts at `i`, when the content is
/// printable ASCII without escapes (and, for a key, without `.`: a flat object then never has
/// a key that a dotted path could be confused with).
#[inline(always)]
fn plain_string_end<const KEY: bool>(b: &[u8], mut i: usize) -> Option<usize> {
    let stops = |x: u64| {
        let mut stops = string_stops(x);
        if KEY {
            stops |= eq_bytes(x, b'.');
        }
        stops
    };
    // Whole words, then the last bytes as one word padded with zeros (which stop).
    while let Some(w) = b.get(i..i + 8) {
        let x = u64::from_le_bytes(w.try_into().unwrap_or([0; 8]));
        let m = stops(x);
        if m != 0 {
            let end = i + first_flagged(m);
            return (b[end] == b'"').then_some(end);
        }
        i += 8;
    }
    let m = stops(word_at(b, i));
    let end = i + first_flagged(m);
    (b.get(end) == Some(&b'"')).then_some(end)
}

/// The end of the run of ASCII digits starting at `i`.
#[inline(always)]
fn digits_end(b: &[u8], mut i: usize) -> usize {
    while let Some(w) = b.get(i..i + 8) {
        let m = non_digits(u64::from_le_bytes(w.try_into().unwrap_or([0; 8])));
        if m != 0 {
            return i + first_flagged(m);
        }
        i += 8;
    }
    // The last bytes, padded with zeros (which are not digits).
    i + first_flagged(non_digits(word_at(b, i)))
}

/// The value of the `k` (1..=8) ASCII digits at the low end of `x`.
#[inline(always)]
fn digits8_value(x: u64, k: usize) -> u64 {
    // Move the digits to the top; the zero bytes shifted in below read as leading zeros.
    let x = x << (8 * (8 - k));
    let x = ((x & 0x0F0F_0F0F_0F0F_0F0F).wrapping_mul(2561)) >> 8;
    let x = ((x & 0x00FF_00FF_00FF_00FF).wrapping_mul(6_553_601)) >> 16;
    ((x & 0x0000_FFFF_0000_FFFF).wrapping_mul(42_949_672_960_001)) >> 32
}

/// `10^k` for `k` in 0..=19.
const POW10_U64: [u64; 20] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
    10_000_000_000,
    100_000_000_000,
    1_000_000_000_000,
    10_000_000_000_000,
    100_000_000_000_000,
    1_000_000_000_000_000,
    10_000_000_000_000_000,
    100_000_000_000_000_000,
    1_000_000_000_000_000_000,
    10_000_000_000_000_000_000,
];

/// The run of ASCII digits starting at `i`: where it ends, and its value (exact when the run
/// has at most 19 digits; wrapped otherwise).
#[inline(always)]
fn digit_run(b: &[u8], mut i: usize) -> (usize, u64) {
    let mut v: u64 = 0;
    while let Some(w) = b.get(i..i + 8) {
        let x = u64::from_le_bytes(w.try_into().unwrap_or([0; 8]));
        if non_digits(x) != 0 {
            return digit_run_tail(v, i, x);
        }
        v = v
            .wrapping_mul(100_000_000)
            .wrapping_add(digits8_value(x, 8));
        i += 8;
    }
    // The last bytes, padded with zeros (which are not digits).
    digit_run_tail(v, i, word_at(b, i))
}

/// The end of [`digit_run`]: the digits at the low end of `x` (the word at `i`), appended to
/// `v`.
#[inline(always)]
fn digit_run_tail(v: u64, i: usize, x: u64) -> (usize, u64) {
    let k = first_flagged(non_digits(x));
    if k == 0 {
        return (i, v);
    }
    (
        i + k,
        v.wrapping_mul(POW10_U64[k])
            .wrapping_add(digits8_value(x, k)),
    )
}

/// The index just after a JSON number starting at `i` (a `-` or a digit), when its syntax is
/// valid up to there (as [`scan_number`], without the value).
#[inline(always)]
fn number_end(b: &[u8], mut i: usize) -> Option<usize> {
    if b.get(i) == Some(&b'-') {
        i += 1;
    }
    match b.get(i)? {
        b'0' => i += 1,
        b'1'..=b'9' => i = digits_end(b, i + 1),
        _ => return None,
    }
    if b.get(i) == Some(&b'.') {
        let end = digits_end(b, i + 1);
        if end == i + 1 {
            return None;
        }
        i = end;
    }
    if let Some(b'e' | b'E') = b.get(i) {
        i += 1;
        if let Some(b'+' | b'-') = b.get(i) {
            i += 1;
        }
        let end = digits_end(b, i);
        if end == i {
            return None;
        }
        i = end;
    }
    Some(i)
}

/// The JSON number starting at `start` (a `-` or a digit), when its syntax is valid up to
/// where it ends. (A digit right after a leading `0` ends the number; the caller then finds no
/// `,` or `}`.)
#[inline(always)]
fn scan_number(b: &[u8], start: usize) -> Option<FlatNumber<'_>> {
    let negative = b.get(start) == Some(&b'-');
    let int_start = start + usize::from(negative);
    let (int_end, int_value) = match b.get(int_start)? {
        b'0' => (int_start + 1, 0),
        b'1'..=b'9' => digit_run(b, int_start),
        _ => return None,
    };
    let (frac_end, frac_value) = if b.get(int_end) == Some(&b'.') {
        let (end, v) = digit_run(b, int_end + 1);
        if end == int_end + 1 {
            return None;
        }
        (end, v)
    } else {
        (int_end, 0)
    };
    let int_digits = int_end - int_start;
    let frac_digits = frac_end - (int_end + usize::from(frac_end > int_end));
    let short = int_digits + frac_digits <= 19;
    let exp_at = frac_end;
    let mut end = frac_end;
    if let Some(b'e' | b'E') = b.get(end) {
        end += 1;
        if let Some(b'+' | b'-') = b.get(end) {
            end += 1;
        }
        let digits = digits_end(b, end);
        if digits == end {
            return None;
        }
        end = digits;
    }
    // (A number of more than 4 GB goes digit by digit too.)
    let exp_at = u32::try_from(exp_at - start).ok();
    let short = short && exp_at.is_some();
    Some(FlatNumber {
        text: &b[start..end],
        significand: if short {
            int_value * POW10_U64[frac_digits] + frac_value
        } else {
            0
        },
        exp_at: exp_at.unwrap_or(0),
        // At most 19 when `short` (the only case it is read).
        frac_digits: frac_digits as u8,
        negative,
        short,
    })
}

impl<'a> FlatNumber<'a> {
    /// The number's text.
    pub fn text(&self) -> &'a [u8] {
        self.text
    }

    /// Its value as serde_json (without `float_roundtrip`) reads it, for a value deserialized
    /// as any number (an integer goes through `u64`/`i64`, as `x as f64`). `None` for what this
    /// does not reproduce: a significand of more than `u64::MAX`, an exponent beyond `i32`, a
    /// number out of the `f64` range (serde_json's error).
    #[inline]
    pub fn to_f64(&self) -> Option<f64> {
        if !self.short {
            // The significand may not fit: serde_json's own digit-by-digit rules.
            return number_f64_by_digits(self.text);
        }
        let positive = !self.negative;
        // At most 19 fraction digits.
        let mut exponent = -i32::from(self.frac_digits);
        let exp_at = self.exp_at as usize;
        if exp_at < self.text.len() {
            exponent = apply_exponent(exponent, self.text.get(exp_at + 1..)?)?;
        } else if self.frac_digits == 0 {
            // serde_json: U64(s) as f64; I64(-s) as f64 or -(s as f64): the same value.
            let f = self.significand as f64;
            return Some(if positive { f } else { -f });
        }
        f64_from_parts(positive, self.significand, exponent)
    }
}

/// serde_json's exponent arithmetic: `exponent` plus the exponent `text` (after the `e`: an
/// optional sign and digits); `None` when it overflows `i32` (serde_json then returns 0 or an
/// error, left to it).
#[inline]
fn apply_exponent(exponent: i32, text: &[u8]) -> Option<i32> {
    let (positive, digits) = match text.first() {
        Some(b'+') => (true, &text[1..]),
        Some(b'-') => (false, &text[1..]),
        _ => (true, text),
    };
    if digits.is_empty() {
        return None;
    }
    let mut exp: i32 = 0;
    for &c in digits {
        if !c.is_ascii_digit() {
            return None;
        }
        let digit = i32::from(c - b'0');
        if overflows_i32(exp, digit) {
            return None;
        }
        exp = exp * 10 + digit;
    }
    Some(if positive {
        exponent.saturating_add(exp)
    } else {
        exponent.saturating_sub(exp)
    })
}

/// serde_json's `overflow!(a * 10 + b, max)`: whether `a * 10 + b` exceeds `max`.
#[inline]
fn overflows_u64(a: u64, digit: u64) -> bool {
    a >= u64::MAX / 10 && (a > u64::MAX / 10 || digit > u64::MAX % 10)
}

#[inline]
fn overflows_i32(a: i32, digit: i32) -> bool {
    a >= i32::MAX / 10 && (a > i32::MAX / 10 || digit > i32::MAX % 10)
}

/// The `f64` serde_json reads from the JSON number `text` ([`FlatNumber::to_f64`]); `None`
/// when `text` is not exactly one JSON number, or is one that is left to serde_json.
pub fn number_f64(text: &[u8]) -> Option<f64> {
    match text.first() {
        Some(b'-' | b'0'..=b'9') => {}
        _ => return None,
    }
    let n = scan_number(text, 0)?;
    if n.text.len() != text.len() {
        return None;
    }
    n.to_f64()
}

/// [`FlatNumber::to_f64`] digit by digit, exactly as serde_json reads a number (for long
/// significands).
#[cold]
fn number_f64_by_digits(text: &[u8]) -> Option<f64> {
    let (positive, mut i) = match text.first() {
        Some(b'-') => (false, 1),
        _ => (true, 0),
    };
    let mut significand: u64 = 0;
    match text.get(i)? {
        b'0' => i += 1,
        b'1'..=b'9' => {
            while let Some(&c @ b'0'..=b'9') = text.get(i) {
                let digit = u64::from(c - b'0');
                if overflows_u64(significand, digit) {
                    return None;
                }
                significand = significand * 10 + digit;
                i += 1;
            }
        }
        _ => return None,
    }
    let mut exponent: i32 = 0;
    let mut float = false;
    if text.get(i) == Some(&b'.') {
        float = true;
        i += 1;
        let start = i;
        while let Some(&c @ b'0'..=b'9') = text.get(i) {
            let digit = u64::from(c - b'0');
            if overflows_u64(significand, digit) {
                return None;
            }
            significand = significand * 10 + digit;
            exponent -= 1;
            i += 1;
        }
        if i == start {
            return None;
        }
    }
    if let Some(b'e' | b'E') = text.get(i) {
        float = true;
        exponent = apply_exponent(exponent, &text[i + 1..])?;
        i = text.len();
    }
    if i != text.len() {
        return None;
    }
    if !float {
        let f = significand as f64;
        return Some(if positive { f } else { -f });
    }
    f64_from_parts(positive, significand, exponent)
}

/// serde_json 1.x `Deserializer::f64_from_parts` without `float_roundtrip`, step by step; `None`
/// where it returns an error (out of range).
#[inline]
fn f64_from_parts(positive: bool, significand: u64, mut exponent: i32) -> Option<f64> {
    let mut f = significand as f64;
    loop {
        match POW10.get(exponent.wrapping_abs() as usize) {
            Some(&pow) => {
                if exponent >= 0 {
                    f *= pow;
                    if f.is_infinite() {
                        return None;
                    }
                } else {
                    f /= pow;
                }
                break;
            }
            None => {
                if f == 0.0 {
                    break;
                }
                if exponent >= 0 {
                    return None;
                }
                f /= 1e308;
                exponent += 308;
            }
        }
    }
    Some(if positive { f } else { -f })
}

/// Powers of ten as serde_json has them (correctly rounded literals).
#[rustfmt::skip]
static POW10: [f64; 309] = [
    1e000, 1e001, 1e002, 1e003, 1e004, 1e005, 1e006, 1e007, 1e008, 1e009, //
    1e010, 1e011, 1e012, 1e013, 1e014, 1e015, 1e016, 1e017, 1e018, 1e019, //
    1e020, 1e021, 1e022, 1e023, 1e024, 1e025, 1e026, 1e027, 1e028, 1e029, //
    1e030, 1e031, 1e032, 1e033, 1e034, 1e035, 1e036, 1e037, 1e038, 1e039, //
    1e040, 1e041, 1e042, 1e043, 1e044, 1e045, 1e046, 1e047, 1e048, 1e049, //
    1e050, 1e051, 1e052, 1e053, 1e054, 1e055, 1e056, 1e057, 1e058, 1e059, //
    1e060, 1e061, 1e062, 1e063, 1e064, 1e065, 1e066, 1e067, 1e068, 1e069, //
    1e070, 1e071, 1e072, 1e073, 1e074, 1e075, 1e076, 1e077, 1e078, 1e079, //
    1e080, 1e081, 1e082, 1e083, 1e084, 1e085, 1e086, 1e087, 1e088, 1e089, //
    1e090, 1e091, 1e092, 1e093, 1e094, 1e095, 1e096, 1e097, 1e098, 1e099, //
    1e100, 1e101, 1e102, 1e103, 1e104, 1e105, 1e106, 1e107, 1e108, 1e109, //
    1e110, 1e111, 1e112, 1e113, 1e114, 1e115, 1e116, 1e117, 1e118, 1e119, //
    1e120, 1e121, 1e122, 1e123, 1e124, 1e125, 1e126, 1e127, 1e128, 1e129, //
    1e130, 1e131, 1e132, 1e133, 1e134, 1e135, 1e136, 1e137, 1e138, 1e139, //
    1e140, 1e141, 1e142, 1e143, 1e144, 1e145, 1e146, 1e147, 1e148, 1e149, //
    1e150, 1e151, 1e152, 1e153, 1e154, 1e155, 1e156, 1e157, 1e158, 1e159, //
    1e160, 1e161, 1e162, 1e163, 1e164, 1e165, 1e166, 1e167, 1e168, 1e169, //
    1e170, 1e171, 1e172, 1e173, 1e174, 1e175, 1e176, 1e177, 1e178, 1e179, //
    1e180, 1e181, 1e182, 1e183, 1e184, 1e185, 1e186, 1e187, 1e188, 1e189, //
    1e190, 1e191, 1e192, 1e193, 1e194, 1e195, 1e196, 1e197, 1e198, 1e199, //
    1e200, 1e201, 1e202, 1e203, 1e204, 1e205, 1e206, 1e207, 1e208, 1e209, //
    1e210, 1e211, 1e212, 1e213, 1e214, 1e215, 1e216, 1e217, 1e218, 1e219, //
    1e220, 1e221, 1e222, 1e223, 1e224, 1e225, 1e226, 1e227, 1e228, 1e229, //
    1e230, 1e231, 1e232, 1e233, 1e234, 1e235, 1e236, 1e237, 1e238, 1e239, //
    1e240, 1e241, 1e242, 1e243, 1e244, 1e245, 1e246, 1e247, 1e248, 1e249, //
    1e250, 1e251, 1e252, 1e253, 1e254, 1e255, 1e256, 1e257, 1e258, 1e259, //
    1e260, 1e261, 1e262, 1e263, 1e264, 1e265, 1e266, 1e267, 1e268, 1e269, //
    1e270, 1e271, 1e272, 1e273, 1e274, 1e275, 1e276, 1e277, 1e278, 1e279, //
    1e280, 1e281, 1e282, 1e283, 1e284, 1e285, 1e286, 1e287, 1e288, 1e289, //
    1e290, 1e291, 1e292, 1e293, 1e294, 1e295, 1e296, 1e297, 1e298, 1e299, //
    1e300, 1e301, 1e302, 1e303, 1e304, 1e305, 1e306, 1e307, 1e308, //
];

#[cfg(test)]
mod tests {
    use super::*;

    fn members(json: &str) -> Option<Vec<(String, String)>> {
        let mut v = Vec::new();
        scan_flat_object(json.as_bytes(), |k, x| {
            let x = match x {
                FlatValue::Number(n) => {
                    let text = String::from_utf8(n.text().to_vec()).expect("ascii");
                    format!("{text} = {:?}", n.to_f64())
                }
                other => format!("{other:?}"),
            };
            v.push((String::from_utf8(k.to_vec()).expect("ascii"), x))
        })
        .then_some(v)
    }

    #[test]
    fn scans_flat_objects_and_refuses_the_rest() {
        let m = members(r#" { "a" : 1.5e3 , "b":null,"c":true,"d":false,"e":"x y","f":-0.25}"#)
            .expect("flat");
        let expected = [
            ("a", "1.5e3 = Some(1500.0)"),
            ("b", "Null"),
            ("c", "Bool(true)"),
            ("d", "Bool(false)"),
            ("e", "Str([120, 32, 121])"),
            ("f", "-0.25 = Some(-0.25)"),
        ];
        assert_eq!(
            m,
            expected
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect::<Vec<_>>()
        );
        assert_eq!(members("{}"), Some(vec![]));
        for refused in [
            "",
            "[]",
            "1",
            r#"{"a":1"#,
            r#"{"a":1,}"#,
            r#"{"a":01}"#,
            r#"{"a":1.}"#,
            r#"{"a":.5}"#,
            r#"{"a":1e}"#,
            r#"{"a":-}"#,
            r#"{"a":+1}"#,
            r#"{"a":nul}"#,
            r#"{"a":[1]}"#,
            r#"{"a":{"b":1}}"#,
            r#"{"\u0061":1}"#,
            r#"{"a":"\n"}"#,
            "{\"a\":\"\t\"}",
            "{\"\u{e9}\":1}",
            r#"{"a":1} x"#,
            r#"{"a.b":1}"#,
            r#"{"a" 1}"#,
            r#"{a:1}"#,
            "{\"a\":1}\u{a0}",
        ] {
            assert_eq!(members(refused), None, "{refused:?}");
        }
    }

    #[test]
    fn expected_keys_are_compared_and_values_skipped() {
        const A: PlainKey = PlainKey::new(b"a");
        const BB: PlainKey = PlainKey::new(b"bb");
        let mut obj = FlatObject::new(br#"{"a":1.5e3, "bb":"x","c":null}"#).unwrap();
        assert!(!obj.next_key_is(BB));
        assert!(obj.next_key_is(A));
        obj.skip_value().unwrap();
        assert!(!obj.next_key_is(A));
        assert!(obj.next_key_is(BB));
        obj.skip_value().unwrap();
        assert_eq!(obj.next_key(), Ok(Some(&b"c"[..])));
        obj.skip_value().unwrap();
        assert!(!obj.next_key_is(A));
        assert_eq!(obj.next_key(), Ok(None));
        // A prefix of a longer key is not the key; whitespace before the colon is for next_key.
        let mut obj = FlatObject::new(br#"{"ab":1}"#).unwrap();
        assert!(!obj.next_key_is(A));
        let mut obj = FlatObject::new(br#"{"a" :1}"#).unwrap();
        assert!(!obj.next_key_is(A));
        assert_eq!(obj.next_key(), Ok(Some(&b"a"[..])));
        // Long keys too.
        const LONG: PlainKey = PlainKey::new(b"a_key_of_twenty_bytes");
        let mut obj =
            FlatObject::new(br#"{"a_key_of_twenty_bytes":1,"a_key_of_twenty_byteZ":2}"#).unwrap();
        assert!(obj.next_key_is(LONG));
        obj.skip_value().unwrap();
        assert!(!obj.next_key_is(LONG));
        for bad in [
            &br#"{"a":01}"#[..],
            br#"{"a":1.}"#,
            br#"{"a":"
"}"#,
            br#"{"a":nul}"#,
        ] {
            let mut obj = FlatObject::new(bad).unwrap();
            assert!(obj.next_key_is(A));
            assert!(
                obj.skip_value().is_err() || obj.next_key().is_err(),
                "{bad:?}"
            );
        }
    }

    #[test]
    #[should_panic(expected = "not a plain key")]
    fn a_dotted_key_is_not_plain() {
        let _ = PlainKey::new(b"a.b");
    }

    #[test]
    fn numbers_as_serde_json_reads_them() {
        for text in [
            "0",
            "-0",
            "1",
            "-1",
            "18446744073709551615",
            "-9223372036854775808",
            "-9223372036854775809",
            "1.5",
            "0.1",
            "1.2345678901234567",
            "2.2250738585072014e-308",
            "5e-324",
            "1e-400",
            "-1e-400",
            "0e999999",
            "1.7976931348623157e308",
            "123456789012345678e-330",
            "1E+2",
            "1e-2",
        ] {
            let ours = number_f64(text.as_bytes()).expect(text);
            let theirs: f64 = serde_json::from_str(text).expect(text);
            assert_eq!(ours.to_bits(), theirs.to_bits(), "{text}");
        }
        for unhandled in [
            "",
            "-",
            "01",
            "1.",
            ".5",
            "1e",
            "1e+",
            "+1",
            "1x",
            "1e400",
            "-1e400",
            "18446744073709551616",
            "1.8446744073709551616",
            "1e2147483648",
            "NaN",
        ] {
            assert_eq!(number_f64(unhandled.as_bytes()), None, "{unhandled}");
        }
    }

    mod words {
        use super::super::*;
        use proptest::prelude::*;

        /// Index of the first byte of `w` that `stop` flags, 8 when none: what the word masks
        /// must give.
        fn first(w: [u8; 8], stop: impl Fn(u8) -> bool) -> usize {
            w.iter().position(|&c| stop(c)).unwrap_or(8)
        }

        fn flagged(mask: u64) -> usize {
            if mask == 0 {
                8
            } else {
                first_flagged(mask)
            }
        }

        fn is_string_stop(c: u8) -> bool {
            c == b'"' || c == b'\\' || !(0x20..0x80).contains(&c)
        }

        #[test]
        fn every_byte_value_at_every_position() {
            for c in 0..=255u8 {
                for p in 0..8 {
                    for fill in [b'a', b'7', b'~'] {
                        let mut w = [fill; 8];
                        w[p] = c;
                        let x = u64::from_le_bytes(w);
                        assert_eq!(flagged(string_stops(x)), first(w, is_string_stop));
                        assert_eq!(flagged(eq_bytes(x, b'.')), first(w, |c| c == b'.'));
                        assert_eq!(
                            flagged(non_digits(x)),
                            first(w, |c| !c.is_ascii_digit()),
                            "{w:?}"
                        );
                    }
                }
            }
        }

        #[test]
        fn words_past_the_end_read_as_zeros() {
            let b = b"0123456789";
            assert_eq!(word_at(b, 0), u64::from_le_bytes(*b"01234567"));
            assert_eq!(word_at(b, 5), u64::from_le_bytes(*b"56789\0\0\0"));
            assert_eq!(word_at(b, 10), 0);
            assert_eq!(word_at(b, 99), 0);
            assert_eq!(word_at(b"12", 1), u64::from(b'2'));
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(20_000))]

            #[test]
            fn masks_find_the_first_stop(w in any::<[u8; 8]>(), digits in "[0-9]{0,8}") {
                // Random bytes, and runs of digits followed by random bytes.
                let mut v = w;
                v[..digits.len()].copy_from_slice(digits.as_bytes());
                for w in [w, v] {
                    let x = u64::from_le_bytes(w);
                    prop_assert_eq!(flagged(string_stops(x)), first(w, is_string_stop));
                    prop_assert_eq!(flagged(eq_bytes(x, b'"')), first(w, |c| c == b'"'));
                    prop_assert_eq!(flagged(non_digits(x)), first(w, |c| !c.is_ascii_digit()));
                }
            }

            #[test]
            fn digit_values(digits in "[0-9]{1,8}", tail in any::<[u8; 8]>()) {
                let k = digits.len();
                let mut w = tail;
                w[..k].copy_from_slice(digits.as_bytes());
                let expected: u64 = digits.parse().unwrap();
                prop_assert_eq!(digits8_value(u64::from_le_bytes(w), k), expected);
            }

            #[test]
            fn digit_runs_anywhere(
                head in "[ -~]{0,12}",
                digits in "[0-9]{1,19}",
                tail in "[^0-9]{0,3}",
            ) {
                let text = format!("{head}{digits}{tail}");
                let b = text.as_bytes();
                let i = head.len();
                let end = i + digits.len();
                prop_assert_eq!(digits_end(b, i), end);
                let expected: u64 = digits.parse().unwrap();
                prop_assert_eq!(digit_run(b, i), (end, expected));
            }
        }
    }
}
