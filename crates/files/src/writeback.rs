//! A file written front to back whose pages go to the disk while it is
//! written, not all at its end.
//!
//! The MCAP output is synced before it is moved into place (a machine that
//! stops just after the rename must not leave an empty file under the final
//! name). On its own that sync writes the whole file out at the end of the
//! run, after the engine has finished: 1.7-2.8 ms of a 3-day replay's 78 ms
//! for its 1.9 MB (2026-12-04). Writing through [`Writeback`] starts the
//! disk's writes every [`EVERY`] bytes, on the thread that writes (the
//! output's own, behind the engine), so that the final sync waits for the
//! last few only (0.4-0.5 ms). Starting the writes is a hint: it waits for
//! nothing, and its errors are those the final sync reports.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};

/// Bytes written between two starts of the disk's writes.
const EVERY: u64 = 256 << 10;

/// `File`, starting the disk's writes every 256 KiB written.
#[derive(Debug)]
pub struct Writeback {
    file: File,
    /// Bytes written since the disk's writes were last started.
    pending: u64,
}

impl Writeback {
    pub fn new(file: File) -> Self {
        Self { file, pending: 0 }
    }

    /// The file, to sync and close.
    pub fn into_inner(self) -> File {
        self.file
    }
}

impl Write for Writeback {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.pending += n as u64;
        if self.pending >= EVERY {
            self.pending = 0;
            start_writes(&self.file);
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for Writeback {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

/// Starts the disk's writes of the file's dirty pages (Linux's
/// `sync_file_range` with `SYNC_FILE_RANGE_WRITE`, which does not wait for
/// them); elsewhere nothing, and the final sync writes everything.
#[cfg(target_os = "linux")]
fn start_writes(file: &File) {
    use std::os::fd::AsRawFd;
    // SAFETY: sync_file_range takes plain integers; the descriptor is open
    // for the call (borrowed from `file`). Offset 0 and length 0: the whole
    // file. Its result is a hint's: ignored (see the module's comment).
    unsafe {
        libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writes(_file: &File) {}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};

    use super::*;

    /// What goes through is the file's content, in order, across several
    /// starts of the disk's writes and a seek back.
    #[test]
    fn writes_what_it_is_given() {
        let mut file = Writeback::new(tempfile::tempfile().unwrap());
        let block: Vec<u8> = (0..=255u8).cycle().take(300_001).collect();
        for _ in 0..8 {
            file.write_all(&block).unwrap();
        }
        file.seek(SeekFrom::Start(1)).unwrap();
        file.write_all(b"x").unwrap();
        file.flush().unwrap();
        let mut file = file.into_inner();
        file.sync_all().unwrap();
        let mut back = Vec::new();
        file.seek(SeekFrom::Start(0)).unwrap();
        file.read_to_end(&mut back).unwrap();
        let mut expected: Vec<u8> = block.repeat(8);
        expected[1] = b'x';
        assert_eq!(back, expected);
    }
}
