//! A fixed number of worker threads fed by a bounded queue. A connection the queue has no room
//! for is refused at once (503) instead of spawning a thread for it, so a flood of connections
//! costs a bounded number of threads and bounded memory.
use std::io;
use std::net::TcpStream;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};

/// Hands connections to the workers; dropping it lets them finish what they hold and exit.
pub struct Pool {
    queue: SyncSender<TcpStream>,
}

/// Why a connection was not queued; the stream comes back so that it can be answered.
pub enum Rejected {
    /// Every worker is busy and the queue is full.
    Full(TcpStream),
    /// The workers are gone (the server is stopping).
    Closed(TcpStream),
}

impl Pool {
    /// Starts `workers` threads (at least one) that each run `handle` on the connections they
    /// take, with room for `queued` connections waiting.
    pub fn start(
        workers: usize,
        queued: usize,
        handle: impl Fn(TcpStream) + Send + Sync + 'static,
    ) -> io::Result<Pool> {
        let (queue, waiting) = sync_channel(queued);
        let waiting = Arc::new(Mutex::new(waiting));
        let handle = Arc::new(handle);
        for i in 0..workers.max(1) {
            let (waiting, handle) = (waiting.clone(), handle.clone());
            std::thread::Builder::new()
                .name(format!("serve-worker-{i}"))
                .spawn(move || work(&waiting, &*handle))?;
        }
        Ok(Pool { queue })
    }

    /// Queues `stream` for the next free worker without waiting.
    pub fn offer(&self, stream: TcpStream) -> Result<(), Rejected> {
        self.queue.try_send(stream).map_err(|e| match e {
            TrySendError::Full(s) => Rejected::Full(s),
            TrySendError::Disconnected(s) => Rejected::Closed(s),
        })
    }
}

fn work(waiting: &Mutex<Receiver<TcpStream>>, handle: &(impl Fn(TcpStream) + ?Sized)) {
    loop {
        // The lock is held only while taking a connection, not while serving it, and nothing
        // panics while holding it; a poisoned lock would still guard a usable receiver.
        let next = waiting.lock().unwrap_or_else(|p| p.into_inner()).recv();
        match next {
            // A panic while serving one connection must not cost the pool a worker for good.
            Ok(stream) => {
                let _ = catch_unwind(AssertUnwindSafe(|| handle(stream)));
            }
            Err(_) => return, // the pool was dropped: the server is stopping
        }
    }
}
