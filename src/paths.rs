//! Whether two paths are one file, so that no command writes its output over one of its inputs.

use std::path::Path;

/// True when `a` and `b` name the same existing file: the same canonical path (`./x`, `d/../x`,
/// a symbolic link), or on Unix the same device and inode (a hard link). A path that does not
/// exist yet is no other file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    if let (Ok(x), Ok(y)) = (a.canonicalize(), b.canonicalize()) {
        if x == y {
            return true;
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_sees_through_dots_links_and_hard_links() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.toml");
        std::fs::write(&a, "x").expect("write");
        assert!(same_file(&a, &dir.path().join(".").join("a.toml")));
        assert!(
            !same_file(&a, &dir.path().join("b.toml")),
            "b does not exist"
        );
        #[cfg(unix)]
        {
            let h = dir.path().join("h.toml");
            std::fs::hard_link(&a, &h).expect("hard link");
            assert!(same_file(&a, &h));
            let s = dir.path().join("s.toml");
            std::os::unix::fs::symlink(&a, &s).expect("symlink");
            assert!(same_file(&s, &a));
        }
        std::fs::write(dir.path().join("c.toml"), "x").expect("write");
        assert!(!same_file(&a, &dir.path().join("c.toml")));
    }
}
