//! Reading a user's text file (a configuration, a scenario, a mapping) with a size limit, so
//! that a path such as `/dev/zero` or a multi-gigabyte file given by mistake fails with an
//! error instead of being read until memory runs out.

use std::io::Read;
use std::path::Path;

/// Largest text file fdd reads whole: 4 MiB. fdd's own configuration and scenario files are a
/// few kilobytes; a calibrated configuration is under 20 kB.
pub const MAX_TEXT_FILE_BYTES: u64 = 4 << 20;

/// Why a text file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: larger than the {limit} bytes a text file may have (is it the right file?)")]
    TooLarge { path: String, limit: u64 },
    #[error("{path}: not UTF-8 text (invalid byte at offset {offset})")]
    NotUtf8 { path: String, offset: usize },
}

/// The whole text of the file at `path`, refusing files over `limit` bytes without reading
/// more than `limit + 1` of them (the length is not trusted: `/dev/zero` and pipes have none).
pub fn read_text_limited(path: &Path, limit: u64) -> Result<String, TextFileError> {
    let name = || path.display().to_string();
    let file = std::fs::File::open(path).map_err(|source| TextFileError::Io {
        path: name(),
        source,
    })?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| TextFileError::Io {
            path: name(),
            source,
        })?;
    if bytes.len() as u64 > limit {
        return Err(TextFileError::TooLarge {
            path: name(),
            limit,
        });
    }
    String::from_utf8(bytes).map_err(|e| TextFileError::NotUtf8 {
        path: name(),
        offset: e.utf8_error().valid_up_to(),
    })
}

/// [`read_text_limited`] with [`MAX_TEXT_FILE_BYTES`].
pub fn read_text(path: &Path) -> Result<String, TextFileError> {
    read_text_limited(path, MAX_TEXT_FILE_BYTES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dev_zero_is_refused_after_the_limit_not_read_forever() {
        let e = read_text_limited(Path::new("/dev/zero"), 1 << 16).unwrap_err();
        assert!(
            matches!(e, TextFileError::TooLarge { limit: 65536, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("/dev/zero"), "{e}");
    }

    #[test]
    fn a_file_at_the_limit_is_read_and_one_byte_more_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.toml");
        std::fs::write(&p, "x = 1\n").unwrap();
        assert_eq!(read_text_limited(&p, 6).unwrap(), "x = 1\n");
        assert!(matches!(
            read_text_limited(&p, 5),
            Err(TextFileError::TooLarge { .. })
        ));
    }

    #[test]
    fn binary_is_named_with_its_offset() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.toml");
        std::fs::write(&p, b"ab\xffcd").unwrap();
        let e = read_text(&p).unwrap_err();
        assert!(matches!(e, TextFileError::NotUtf8 { offset: 2, .. }), "{e}");
    }
}
