//! The layout pass beside the replay: a replay that starts before the pass
//! has checked every chunk.
//!
//! [`super::RecordingReader::open`] lays a file out whole before its first
//! message: every chunk decompressed and checked (a third of a 3-day
//! replay's time on two cores goes there before the engine's first step).
//! A replay can start sooner when the file says where its chunks are and
//! when each begins without being decompressed ([`layout::chunk_heads`]): the pass
//! then runs on a thread of its own and hands each chunk over as it adds
//! it, in file order, with its messages when it keeps them; the replay takes
//! a chunk when the time frontier reaches it, waiting for the pass if it
//! is not there yet. The pass's checks still come first: a chunk is
//! replayed only once the pass has added it and every chunk before it, and
//! what the pass finds wrong anywhere else in the file is the error the
//! reader reports, before any error found later in the replay
//! ([`super::RecordingReader::open_beside`]).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;
use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;

use super::layout::{self, Channels, ChunkInfo, Fed, Layout};
use crate::error::InputError;

/// The layout pass running beside the replay, and what it handed over.
pub(super) struct Feed {
    chunks: Receiver<Fed>,
    pass: Option<JoinHandle<Result<Layout, InputError>>>,
    /// Chunks handed over and not yet taken, by number.
    handed: HashMap<u64, ChunkInfo>,
    /// Chunks handed over so far.
    received: u64,
    /// The pass's result, once it has ended.
    ended: Option<Result<Layout, InputError>>,
}

impl Feed {
    /// Starts the layout pass over `file` (a second handle on the file the
    /// replay reads) on a thread of its own.
    pub(super) fn start(path: &Path, file: File) -> std::io::Result<Self> {
        let (sender, chunks) = std::sync::mpsc::channel();
        let path = path.to_path_buf();
        let pass = std::thread::Builder::new()
            .name("tortwin-layout".to_string())
            .spawn(move || layout::scan_feeding(&path, &mut BufReader::new(file), sender))?;
        Ok(Self {
            chunks,
            pass: Some(pass),
            handed: HashMap::new(),
            received: 0,
            ended: None,
        })
    }

    /// Chunk `number` as the pass added it, with the channels known then
    /// (merged into `channels`); waits for the pass to get there. The
    /// pass's error if it failed first, at or before the chunk.
    pub(super) fn take(
        &mut self,
        number: u64,
        channels: &mut Channels,
    ) -> Result<Option<ChunkInfo>, InputError> {
        while self.received <= number && self.ended.is_none() {
            self.wait_for_one(channels);
        }
        if let Some(chunk) = self.handed.remove(&number) {
            return Ok(Some(chunk));
        }
        match &self.ended {
            Some(Err(e)) => Err(e.clone()),
            _ => Ok(None),
        }
    }

    /// Waits for the pass to end: the file's layout (its chunks without
    /// their messages) or the first thing wrong with the file. The chunks
    /// handed over meanwhile wait to be taken, as before.
    pub(super) fn finish(&mut self, channels: &mut Channels) -> Result<&Layout, InputError> {
        while self.ended.is_none() {
            self.wait_for_one(channels);
        }
        match &self.ended {
            Some(Ok(layout)) => Ok(layout),
            Some(Err(e)) => Err(e.clone()),
            None => unreachable!("the loop above ends with the pass"),
        }
    }

    /// Waits for the pass's next chunk, or its end.
    fn wait_for_one(&mut self, channels: &mut Channels) {
        match self.chunks.recv() {
            Ok((chunk, known)) => self.receive(chunk, known, channels),
            Err(_) => self.end(),
        }
    }

    fn receive(&mut self, chunk: ChunkInfo, known: Channels, channels: &mut Channels) {
        self.received += 1;
        channels.extend(known);
        self.handed.insert(chunk.number, chunk);
    }

    /// The pass has dropped its sender: its result (a panic in it goes on
    /// here, as it would have on the reader's thread).
    fn end(&mut self) {
        let Some(pass) = self.pass.take() else {
            return;
        };
        self.ended = Some(match pass.join() {
            Ok(result) => result,
            Err(panic) => std::panic::resume_unwind(panic),
        });
    }
}
