//! The MCAP writer on a thread of its own: the engine's thread serializes
//! each message into a batch and hands the batch over when it is full;
//! chunk compression (zstd at a high level, about a second per month of
//! traffic) runs beside the engine instead of after every chunk's worth of
//! it. Batches (about 64 kB of messages each) cross through the workspace's
//! one batched hand-over (`tortwin_handover`: a wake-up per message cost the
//! engine's thread a tenth of its time; the batches travel back for reuse).
//! The writer sees the same messages in the same order either way: the file
//! is the same.

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use tortwin_handover::{Filler, Gone};

use crate::files::Writeback;

use super::McapError;

pub(super) type Writer = mcap::Writer<BufWriter<Writeback>>;

/// Batches in flight between the threads.
const QUEUE: usize = 16;

/// A batch is handed over once its messages hold this many bytes.
const BATCH_BYTES: usize = 64 << 10;

/// A message of a batch: its header, where its bytes are, its topic.
struct Entry {
    header: mcap::records::MessageHeader,
    start: usize,
    end: usize,
    topic: &'static str,
}

/// Messages for the writer thread, their bytes one after the other.
struct Batch {
    bytes: Vec<u8>,
    entries: Vec<Entry>,
}

impl tortwin_handover::Batch for Batch {
    fn fresh() -> Self {
        Batch {
            bytes: Vec::new(),
            entries: Vec::new(),
        }
    }
    fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
    fn clear(&mut self) {
        self.bytes.clear();
        self.entries.clear();
    }
}

/// The sending end; the writer comes back from [`WriterThread::close`].
pub(super) struct WriterThread {
    jobs: Filler<Batch>,
    thread: Option<JoinHandle<Result<Writer, McapError>>>,
    path: PathBuf,
}

impl WriterThread {
    /// Starts the thread that writes to `writer`; `path` names the output in
    /// errors; `behind`: the thread runs behind the engine (a replay's
    /// output, not a live twin's: [`tortwin_handover::behind_the_engine`]).
    pub(super) fn start(
        writer: Writer,
        path: &Path,
        behind: bool,
    ) -> Result<WriterThread, McapError> {
        let (jobs, incoming) = tortwin_handover::channel::<Batch>(QUEUE);
        let thread_path = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("tortwin-mcap".to_owned())
            .spawn(move || {
                if behind {
                    tortwin_handover::behind_the_engine();
                }
                let mut writer = writer;
                while let Some(batch) = incoming.take() {
                    for e in &batch.entries {
                        writer
                            .write_to_known_channel(&e.header, &batch.bytes[e.start..e.end])
                            .map_err(|source| McapError::Mcap {
                                path: thread_path.clone(),
                                what: format!("writing {}", e.topic),
                                source,
                            })?;
                    }
                    incoming.give_back(batch);
                }
                Ok(writer)
            })
            .map_err(|source| McapError::Io {
                path: path.to_path_buf(),
                what: "starting the writer thread",
                source,
            })?;
        Ok(WriterThread {
            jobs,
            thread: Some(thread),
            path: path.to_path_buf(),
        })
    }

    /// Adds a message: `serialize` writes its bytes to the end of the
    /// buffer it is given (on its error they are dropped again). Hands the
    /// batch to the writer thread when it is full; if that thread has
    /// stopped, its error.
    pub(super) fn push(
        &mut self,
        header: mcap::records::MessageHeader,
        topic: &'static str,
        serialize: impl FnOnce(&mut Vec<u8>) -> Result<(), McapError>,
    ) -> Result<(), McapError> {
        if self.jobs.is_closed() {
            return Err(McapError::Finished {
                path: self.path.clone(),
            });
        }
        let batch = self.jobs.batch();
        let start = batch.bytes.len();
        if let Err(e) = serialize(&mut batch.bytes) {
            batch.bytes.truncate(start);
            return Err(e);
        }
        let end = batch.bytes.len();
        batch.entries.push(Entry {
            header,
            start,
            end,
            topic,
        });
        if end >= BATCH_BYTES {
            self.hand_over()?;
        }
        Ok(())
    }

    /// Sends the batch being filled (if it has messages) and takes a spare
    /// one; if the thread has stopped, its error.
    fn hand_over(&mut self) -> Result<(), McapError> {
        match self.jobs.hand_over() {
            Ok(()) => Ok(()),
            Err(Gone) if self.jobs.is_closed() => Err(McapError::Finished {
                path: self.path.clone(),
            }),
            // The thread stopped on an error: that error.
            Err(Gone) => match self.join() {
                Err(e) => Err(e),
                Ok(_) => Err(McapError::Finished {
                    path: self.path.clone(),
                }),
            },
        }
    }

    /// Hands over what is left, waits for the thread to write everything;
    /// the writer, or the thread's error.
    pub(super) fn close(&mut self) -> Result<Writer, McapError> {
        if !self.jobs.is_closed() {
            self.hand_over()?;
        }
        self.join()
    }

    /// Stops the thread after what it was given; the writer, or its error.
    fn join(&mut self) -> Result<Writer, McapError> {
        self.jobs.close();
        let Some(thread) = self.thread.take() else {
            return Err(McapError::Finished {
                path: self.path.clone(),
            });
        };
        match thread.join() {
            Ok(result) => result,
            Err(_) => Err(McapError::Io {
                path: self.path.clone(),
                what: "writing (the writer thread panicked)",
                source: std::io::Error::other("writer thread panicked"),
            }),
        }
    }
}

impl Drop for WriterThread {
    fn drop(&mut self) {
        // Stop and join the thread without handing over the rest (the
        // output is abandoned): its writer (and file) closes before the
        // temporary file is deleted.
        let _ = self.join();
    }
}
