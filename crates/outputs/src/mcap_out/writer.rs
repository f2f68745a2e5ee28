//! The MCAP writer on a thread of its own: the engine's thread serializes
//! each message into a batch and hands the batch over when it is full;
//! chunk compression (zstd at a high level, about a second per month of
//! traffic) runs beside the engine instead of after every chunk's worth of
//! it. Batches (about 64 kB of messages each) rather than single messages
//! cross the channel: a hand-over wakes the other thread, and a wake-up per
//! message cost the engine's thread a tenth of its time. The batches travel
//! back for reuse, so the steady state allocates nothing. The writer sees
//! the same messages in the same order either way: the file is the same.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use super::McapError;

pub(super) type Writer = mcap::Writer<BufWriter<File>>;

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
#[derive(Default)]
struct Batch {
    bytes: Vec<u8>,
    entries: Vec<Entry>,
}

/// The sending end; the writer comes back from [`WriterThread::close`].
pub(super) struct WriterThread {
    jobs: Option<SyncSender<Batch>>,
    spare: Receiver<Batch>,
    /// The batch being filled.
    batch: Batch,
    thread: Option<JoinHandle<Result<Writer, McapError>>>,
    path: PathBuf,
}

impl WriterThread {
    /// Starts the thread that writes to `writer`; `path` names the output in errors.
    pub(super) fn start(writer: Writer, path: &Path) -> Result<WriterThread, McapError> {
        let (jobs, incoming) = sync_channel::<Batch>(QUEUE);
        let (give_back, spare) = sync_channel::<Batch>(QUEUE + 1);
        let thread_path = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("tortwin-mcap".to_owned())
            .spawn(move || {
                let mut writer = writer;
                for mut batch in incoming {
                    for e in &batch.entries {
                        writer
                            .write_to_known_channel(&e.header, &batch.bytes[e.start..e.end])
                            .map_err(|source| McapError::Mcap {
                                path: thread_path.clone(),
                                what: format!("writing {}", e.topic),
                                source,
                            })?;
                    }
                    batch.bytes.clear();
                    batch.entries.clear();
                    // The engine's side may have stopped taking them back.
                    let _ = give_back.try_send(batch);
                }
                Ok(writer)
            })
            .map_err(|source| McapError::Io {
                path: path.to_path_buf(),
                what: "starting the writer thread",
                source,
            })?;
        Ok(WriterThread {
            jobs: Some(jobs),
            spare,
            batch: Batch::default(),
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
        if self.jobs.is_none() {
            return Err(McapError::Finished {
                path: self.path.clone(),
            });
        }
        let start = self.batch.bytes.len();
        if let Err(e) = serialize(&mut self.batch.bytes) {
            self.batch.bytes.truncate(start);
            return Err(e);
        }
        self.batch.entries.push(Entry {
            header,
            start,
            end: self.batch.bytes.len(),
            topic,
        });
        if self.batch.bytes.len() >= BATCH_BYTES {
            self.hand_over()?;
        }
        Ok(())
    }

    /// Sends the batch being filled (if it has messages) and takes a spare
    /// one; if the thread has stopped, its error.
    fn hand_over(&mut self) -> Result<(), McapError> {
        if self.batch.entries.is_empty() {
            return Ok(());
        }
        let next = self.spare.try_recv().unwrap_or_default();
        let full = std::mem::replace(&mut self.batch, next);
        let sent = match &self.jobs {
            Some(jobs) => jobs.send(full),
            None => {
                return Err(McapError::Finished {
                    path: self.path.clone(),
                })
            }
        };
        match sent {
            Ok(()) => Ok(()),
            // The thread stopped on an error: that error.
            Err(_) => match self.join() {
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
        if self.jobs.is_some() {
            self.hand_over()?;
        }
        self.join()
    }

    /// Stops the thread after what it was given; the writer, or its error.
    fn join(&mut self) -> Result<Writer, McapError> {
        drop(self.jobs.take());
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
