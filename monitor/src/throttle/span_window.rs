//! The range (max - min) of the last `cap` values of a signal, in amortized O(1) per push and
//! without allocation: two monotonic queues (the candidates for the maximum and the minimum).
//! The plate and frozen-TPS tests ask for the span of a 200-sample window every step; a scan
//! of the window cost about 8,000 instructions per 1 ms frame.

/// Largest window.
pub const CAPACITY: usize = 512;

/// A fixed-capacity circular queue of (sample index, value).
#[derive(Debug, Clone)]
struct Queue {
    buf: [(u64, f64); CAPACITY],
    head: usize,
    len: usize,
}

impl Queue {
    fn new() -> Self {
        Self {
            buf: [(0, 0.0); CAPACITY],
            head: 0,
            len: 0,
        }
    }
    fn front(&self) -> Option<(u64, f64)> {
        (self.len > 0).then(|| self.buf[self.head])
    }
    fn back(&self) -> Option<(u64, f64)> {
        (self.len > 0).then(|| self.buf[(self.head + self.len - 1) % CAPACITY])
    }
    fn pop_front(&mut self) {
        self.head = (self.head + 1) % CAPACITY;
        self.len -= 1;
    }
    fn pop_back(&mut self) {
        self.len -= 1;
    }
    fn push_back(&mut self, item: (u64, f64)) {
        // The queue never holds more than the window's `cap <= CAPACITY` items: the caller
        // evicts the oldest first.
        self.buf[(self.head + self.len) % CAPACITY] = item;
        self.len += 1;
    }
}

/// The last `cap` values pushed: how many, the latest, and their range.
#[derive(Debug, Clone)]
pub struct SpanWindow {
    cap: usize,
    pushed: u64,
    last: Option<f64>,
    max_q: Queue,
    min_q: Queue,
}

impl SpanWindow {
    /// A window of `cap` values (clamped to 1..=[`CAPACITY`]).
    pub fn new(cap: usize) -> Self {
        Self {
            cap: cap.clamp(1, CAPACITY),
            pushed: 0,
            last: None,
            max_q: Queue::new(),
            min_q: Queue::new(),
        }
    }

    /// Window length (values).
    pub fn cap(&self) -> usize {
        self.cap
    }

    /// Pushes `v`; a NaN counts as a value but takes no part in the range.
    pub fn push(&mut self, v: f64) {
        let i = self.pushed;
        self.pushed += 1;
        self.last = Some(v);
        let oldest = (i + 1).saturating_sub(self.cap as u64);
        for q in [&mut self.max_q, &mut self.min_q] {
            while q.front().is_some_and(|(j, _)| j < oldest) {
                q.pop_front();
            }
        }
        if v.is_nan() {
            return;
        }
        while self.max_q.back().is_some_and(|(_, b)| b <= v) {
            self.max_q.pop_back();
        }
        self.max_q.push_back((i, v));
        while self.min_q.back().is_some_and(|(_, b)| b >= v) {
            self.min_q.pop_back();
        }
        self.min_q.push_back((i, v));
    }

    /// The window's length (values).
    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// The window holds `cap` values.
    pub fn full(&self) -> bool {
        self.pushed >= self.cap as u64
    }

    /// Largest minus smallest value in the window (-inf when it holds no number).
    pub fn span(&self) -> f64 {
        match (self.max_q.front(), self.min_q.front()) {
            (Some((_, hi)), Some((_, lo))) => hi - lo,
            _ => f64::NEG_INFINITY,
        }
    }

    /// The latest value.
    pub fn last(&self) -> Option<f64> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The span equals a scan of the last `cap` values, for random walks with repeats and NaNs,
    /// at several window lengths.
    #[test]
    fn span_equals_a_scan_of_the_window() {
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for cap in [1, 2, 3, 7, 200, 512, 600] {
            let mut w = SpanWindow::new(cap);
            let mut all: Vec<f64> = Vec::new();
            let mut x = 0.0;
            for k in 0..5000 {
                let r = rnd();
                x = match r % 10 {
                    0 => x,
                    1 => f64::NAN,
                    _ => (if x.is_nan() { 0.0 } else { x }) + ((r >> 8) % 200) as f64 / 100.0 - 1.0,
                };
                w.push(x);
                all.push(x);
                let n = w.cap();
                let tail = &all[all.len().saturating_sub(n)..];
                let (lo, hi) = tail
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                        (a.min(v), b.max(v))
                    });
                let expect = hi - lo;
                let got = w.span();
                assert!(
                    got == expect || (got == f64::NEG_INFINITY && expect.is_nan()),
                    "cap {cap}, step {k}: span {got}, scan {expect}"
                );
                assert_eq!(w.full(), all.len() >= n);
                assert_eq!(w.last().map(f64::to_bits), Some(x.to_bits()));
            }
        }
    }
}
