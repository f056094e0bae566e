//! The message passing that sort-last compositing needs ([`Communicator`]), and an in-process
//! implementation with one thread per rank ([`FakeCluster`]) for tests and for running the
//! protocol without MPI. The MPI implementation lives in `crates/mpi` (issue 32), outside the
//! default workspace (MPI point-to-point calls with buffered sends).

use super::{DistributedError, Result};
use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender, channel};

/// Point-to-point messages among `size()` ranks. Messages from one rank to another arrive in
/// the order they were sent (as MPI guarantees for one communicator and tag). A send must not
/// wait for the matching receive (buffered, or non-blocking with the wait deferred), because
/// every rank sends to every other before it receives.
pub trait Communicator {
    /// This process's rank, in `0..size()`.
    fn rank(&self) -> usize;
    /// The number of ranks (≥ 1).
    fn size(&self) -> usize;
    /// Sends `data` to rank `to` (itself included).
    fn send(&self, to: usize, data: Vec<u8>) -> Result<()>;
    /// The next message from rank `from` (itself included), waiting for it.
    fn recv(&self, from: usize) -> Result<Vec<u8>>;
}

/// `n` ranks in one process, one thread each, connected by channels.
#[derive(Debug, Clone, Copy)]
pub struct FakeCluster {
    /// The number of ranks (≥ 1).
    pub size: usize,
}

/// One rank of a [`FakeCluster`].
#[derive(Debug)]
pub struct FakeComm {
    rank: usize,
    /// `to[r]`: the channel to rank `r`.
    to: Vec<Sender<Vec<u8>>>,
    /// `from[r]`: the channel from rank `r`.
    from: Vec<Mutex<Receiver<Vec<u8>>>>,
}

impl Communicator for FakeComm {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.to.len()
    }

    fn send(&self, to: usize, data: Vec<u8>) -> Result<()> {
        self.to
            .get(to)
            .ok_or(DistributedError::Protocol(
                "a send to a rank that does not exist",
            ))?
            .send(data)
            .map_err(|_| DistributedError::Protocol("a send to a rank that has exited"))
    }

    fn recv(&self, from: usize) -> Result<Vec<u8>> {
        let rx = self.from.get(from).ok_or(DistributedError::Protocol(
            "a receive from a rank that does not exist",
        ))?;
        let rx = rx
            .lock()
            .map_err(|_| DistributedError::Protocol("a poisoned channel"))?;
        rx.recv()
            .map_err(|_| DistributedError::Protocol("a rank exited without sending"))
    }
}

impl FakeCluster {
    /// Runs `f` on every rank, each in its own thread, and returns the ranks' results in rank
    /// order. A rank that panics makes this panic with that rank's panic, after the others have
    /// finished or failed.
    pub fn run<T: Send>(self, f: impl Fn(&FakeComm) -> T + Sync) -> Vec<T> {
        let n = self.size.max(1);
        // senders[a][b] sends from a to b; receivers[b][a] receives at b from a.
        let mut senders: Vec<Vec<Sender<Vec<u8>>>> = (0..n).map(|_| Vec::new()).collect();
        let mut receivers: Vec<Vec<Option<Receiver<Vec<u8>>>>> =
            (0..n).map(|_| (0..n).map(|_| None).collect()).collect();
        for (a, row) in senders.iter_mut().enumerate() {
            for rx_row in receivers.iter_mut() {
                let (tx, rx) = channel();
                row.push(tx);
                rx_row[a] = Some(rx);
            }
        }
        let comms: Vec<FakeComm> = senders
            .into_iter()
            .zip(receivers)
            .enumerate()
            .map(|(rank, (to, from))| FakeComm {
                rank,
                to,
                from: from.into_iter().flatten().map(Mutex::new).collect(),
            })
            .collect();
        std::thread::scope(|s| {
            let handles: Vec<_> = comms.iter().map(|c| s.spawn(|| f(c))).collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .collect()
        })
    }
}
