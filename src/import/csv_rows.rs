//! Streaming CSV rows for `fdd import`: one row in memory at a time, each with the number of
//! the line it starts on, so every error names the file, the line and the column.
//!
//! The `csv` crate parses (quotes, `\n`, `\r\n` and `\r` line ends; blank lines skipped). Two
//! things it does not do are done here:
//!
//! - **Line numbers.** The parser's position before a read is where the previous row ended,
//!   before any blank lines, and a `\r\n` ending is only finished on the next read; so a row's
//!   line is worked out from where it ends instead: the parser's line after the read, less
//!   one if the last byte taken was the row's `\n`, less the line breaks inside its (quoted)
//!   fields. The last byte taken is looked up in `Tap`, which keeps the bytes the parser
//!   was given most recently (its read-ahead is one 8 KiB buffer).
//! - **A bound on a row's length.** A row (with the parser's read-ahead) may take at most
//!   [`MAX_ROW_BYTES`]; `/dev/zero` or a binary file given by mistake fails at once instead of
//!   filling the memory.
//!
//! Fields are not trimmed by the parser (so the line breaks in them can be counted); the
//! callers trim spaces around names and numbers.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use super::ImportError;

/// Longest row (and header) read: 1 MiB. A row of a few hundred numeric columns is a few kB.
pub const MAX_ROW_BYTES: u64 = 1 << 20;

/// Read-ahead of the CSV parser (bytes), counted against [`MAX_ROW_BYTES`] on top.
const PARSER_BUFFER: usize = 8 * 1024;

/// What [`Tap`] shares with [`CsvRows`].
#[derive(Default)]
struct TapState {
    /// Bytes given to the parser since the last row began.
    since_reset: u64,
    /// The row limit was hit.
    tripped: bool,
    /// The last bytes given to the parser (at most twice its buffer), ending at `delivered`.
    tail: VecDeque<u8>,
    /// Bytes given to the parser in all.
    delivered: u64,
}

impl TapState {
    /// The byte at file offset `at`, if still kept.
    fn byte_at(&self, at: u64) -> Option<u8> {
        let first = self.delivered - self.tail.len() as u64;
        if at < first || at >= self.delivered {
            return None;
        }
        self.tail.get(usize::try_from(at - first).ok()?).copied()
    }
}

/// The file as the parser reads it: fails once a row runs past the limit, and keeps the last
/// bytes read.
struct Tap {
    inner: File,
    state: Rc<RefCell<TapState>>,
    limit: u64,
}

impl Read for Tap {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut st = self.state.borrow_mut();
        if st.since_reset > self.limit {
            st.tripped = true;
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "row too long",
            ));
        }
        let n = self.inner.read(buf)?;
        let got = buf.get(..n).unwrap_or_default();
        st.since_reset += n as u64;
        st.delivered += n as u64;
        st.tail.extend(got);
        let excess = st.tail.len().saturating_sub(2 * PARSER_BUFFER);
        st.tail.drain(..excess);
        Ok(n)
    }
}

/// The rows of one CSV file after its header.
pub struct CsvRows {
    file: PathBuf,
    reader: csv::Reader<Tap>,
    tap: Rc<RefCell<TapState>>,
    header: Vec<String>,
    record: csv::ByteRecord,
    /// Line the current row starts on (1 = the header).
    line: u64,
    /// Line the current row ends on.
    last_line: u64,
    /// Bytes of the file, for the progress bar (0 when unknown, e.g. a pipe).
    len: u64,
}

impl CsvRows {
    /// Opens `path` and reads its header (the first line: column names, UTF-8).
    pub fn open(path: &Path, delimiter: u8) -> Result<Self, ImportError> {
        let io = |source| ImportError::Read {
            file: path.to_path_buf(),
            source,
        };
        let inner = File::open(path).map_err(io)?;
        let len = inner
            .metadata()
            .ok()
            .filter(|m| m.is_file())
            .map_or(0, |m| m.len());
        let tap = Rc::new(RefCell::new(TapState::default()));
        let limited = Tap {
            inner,
            state: Rc::clone(&tap),
            limit: MAX_ROW_BYTES + PARSER_BUFFER as u64,
        };
        let reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .delimiter(delimiter)
            .trim(csv::Trim::None)
            .buffer_capacity(PARSER_BUFFER)
            .from_reader(limited);
        let mut rows = CsvRows {
            file: path.to_path_buf(),
            reader,
            tap,
            header: Vec::new(),
            record: csv::ByteRecord::new(),
            line: 1,
            last_line: 0,
            len,
        };
        if !rows.read_record()? {
            return Err(rows.error(1, None, "empty file: no header line with the column names"));
        }
        let mut header = Vec::with_capacity(rows.record.len());
        for (i, f) in rows.record.iter().enumerate() {
            // A UTF-8 byte-order mark before the first name (spreadsheet exports) is no part of it.
            let f = if i == 0 {
                f.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(f)
            } else {
                f
            };
            match std::str::from_utf8(f) {
                Ok(name) => header.push(name.trim().to_string()),
                Err(_) => {
                    return Err(rows.error(
                        rows.line,
                        Some((i, String::new())),
                        "the header's column name is not UTF-8 text (is this a CSV file?)",
                    ))
                }
            }
        }
        rows.header = header;
        Ok(rows)
    }

    /// The CSV file.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// The column names.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// Bytes of the file (0 when unknown).
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// Bytes read so far.
    pub fn position(&self) -> u64 {
        self.reader.position().byte()
    }

    /// Line of the current row.
    pub fn line(&self) -> u64 {
        self.line
    }

    fn read_record(&mut self) -> Result<bool, ImportError> {
        self.tap.borrow_mut().since_reset = 0;
        let next = self.last_line + 1;
        match self.reader.read_byte_record(&mut self.record) {
            Ok(false) => Ok(false),
            Ok(true) => {
                let pos = self.reader.position();
                let ended_by_newline = pos
                    .byte()
                    .checked_sub(1)
                    .and_then(|at| self.tap.borrow().byte_at(at))
                    == Some(b'\n');
                self.last_line = pos.line() - u64::from(ended_by_newline);
                let breaks = self
                    .record
                    .as_slice()
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count();
                self.line = self.last_line.saturating_sub(breaks as u64).max(next);
                Ok(true)
            }
            Err(_) if self.tap.borrow().tripped => Err(self.error(
                next,
                None,
                format!("a row longer than {MAX_ROW_BYTES} bytes (is this a CSV file?)"),
            )),
            Err(e) => {
                let line = e.position().map_or(next, |p| p.line());
                Err(self.error(line, None, e.to_string()))
            }
        }
    }

    /// Reads the next row, checked to have as many fields as the header ([`record`](Self::record));
    /// `false` at the end.
    pub fn next_row(&mut self) -> Result<bool, ImportError> {
        if !self.read_record()? {
            return Ok(false);
        }
        if self.record.len() != self.header.len() {
            return Err(self.error(
                self.line,
                None,
                format!(
                    "{} fields, the header has {} columns",
                    self.record.len(),
                    self.header.len()
                ),
            ));
        }
        Ok(true)
    }

    /// The current row's fields.
    pub fn record(&self) -> &csv::ByteRecord {
        &self.record
    }

    /// The error at `line` (and column `(index, name)`), in this file.
    pub fn error(
        &self,
        line: u64,
        column: Option<(usize, String)>,
        message: impl Into<String>,
    ) -> ImportError {
        ImportError::Csv {
            file: self.file.clone(),
            line,
            column: column.map(|(i, name)| {
                let name = if name.is_empty() {
                    self.header.get(i).cloned().unwrap_or_default()
                } else {
                    name
                };
                (i + 1, name)
            }),
            message: message.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (line, first field) of every row of `text`.
    fn lines(text: &[u8]) -> Vec<(u64, String)> {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("x.csv");
        std::fs::write(&p, text).expect("write");
        let mut rows = CsvRows::open(&p, b',').expect("header");
        let mut out = Vec::new();
        while rows.next_row().expect("row") {
            let f = String::from_utf8_lossy(rows.record().get(0).unwrap_or_default());
            out.push((rows.line(), f.trim().to_string()));
        }
        out
    }

    #[test]
    fn rows_know_the_line_they_start_on() {
        let want = |v: &[(u64, &str)]| -> Vec<(u64, String)> {
            v.iter().map(|(l, s)| (*l, s.to_string())).collect()
        };
        assert_eq!(lines(b"a,b\n1,2\n3,4\n"), want(&[(2, "1"), (3, "3")]));
        assert_eq!(lines(b"a,b\r\n1,2\r\n3,4\r\n"), want(&[(2, "1"), (3, "3")]));
        assert_eq!(lines(b"a,b\n1,2\n3,4"), want(&[(2, "1"), (3, "3")]));
        assert_eq!(lines(b"a,b\r\n1,2\r\n3,4"), want(&[(2, "1"), (3, "3")]));
        // Blank lines before a row, and after the header.
        assert_eq!(
            lines(b"a,b\n\n1,2\n\n\n3,4\n\n"),
            want(&[(3, "1"), (6, "3")])
        );
        assert_eq!(
            lines(b"a,b\r\n\r\n1,2\r\n\r\n\r\n3,4\r\n"),
            want(&[(3, "1"), (6, "3")])
        );
        // A quoted field over two lines: the row starts on its first.
        assert_eq!(
            lines(b"a,b\n\"x\ny\",2\n3,4\n"),
            want(&[(2, "x\ny"), (4, "3")])
        );
        assert_eq!(
            lines(b"a,b\r\n\"x\r\ny\",2\r\n3,4\r\n"),
            want(&[(2, "x\r\ny"), (4, "3")])
        );
        // Lines longer than the tap keeps.
        let long = "9".repeat(40_000);
        let text = format!("a,b\n{long},1\n\n{long},2\n");
        let got = lines(text.as_bytes());
        assert_eq!(got.iter().map(|(l, _)| *l).collect::<Vec<_>>(), [2, 4]);
    }

    #[test]
    fn a_row_over_the_limit_is_refused_on_its_line() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("x.csv");
        let big = "9".repeat(MAX_ROW_BYTES as usize + 3 * PARSER_BUFFER);
        std::fs::write(&p, format!("a\n1\n\n{big}\n")).expect("write");
        let mut rows = CsvRows::open(&p, b',').expect("header");
        assert!(rows.next_row().expect("row 2"));
        let e = rows.next_row().expect_err("too long").to_string();
        assert!(e.contains("line 3: a row longer than"), "{e}");
        let e = CsvRows::open(Path::new("/dev/zero"), b',')
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("/dev/zero: line 1: a row longer than"), "{e}");
    }
}
