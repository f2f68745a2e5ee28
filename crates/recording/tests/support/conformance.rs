//! The MCAP project's conformance files (../mcap-conformance, its README
//! says where they come from), shared by the reader's test beside this
//! crate and the binary's in the workspace's tests/cli_replay.rs.

use std::path::{Path, PathBuf};

/// Every `.mcap` of the suite under `data` (its `data` folder), sorted.
pub fn conformance_files(data: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for group in std::fs::read_dir(data).unwrap() {
        for entry in std::fs::read_dir(group.unwrap().path()).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "mcap") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}
