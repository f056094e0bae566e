//! [`World`]: the engine's [`Communicator`] on `MPI_COMM_WORLD`.

use mpi::traits::{Communicator as _, Destination, Source};
use volsplat::distributed::{Communicator, DistributedError};

/// MPI point-to-point messages on `MPI_COMM_WORLD`: buffered sends (`MPI_Bsend`, into the
/// buffer `main` attaches), so every rank may send to every rank before it receives, as
/// [`Communicator`] requires; a message to itself is queued in memory.
pub struct World {
    /// `MPI_COMM_WORLD`.
    pub world: mpi::topology::SimpleCommunicator,
    /// The messages this rank sent itself and has not received yet, oldest first.
    pending: std::sync::Mutex<Vec<Vec<u8>>>,
}

impl World {
    /// The world of `universe`, whose attached buffer (`Universe::set_buffer_size`) must hold
    /// every message a rank sends before it receives.
    pub fn new(universe: &mpi::environment::Universe) -> World {
        World {
            world: universe.world(),
            pending: std::sync::Mutex::new(Vec::new()),
        }
    }
}

impl Communicator for World {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn send(&self, to: usize, data: Vec<u8>) -> std::result::Result<(), DistributedError> {
        if to >= self.size() {
            return Err(DistributedError::Protocol(
                "a send to a rank that does not exist",
            ));
        }
        // A length first, then the bytes: the receiver sizes its buffer.
        let p = self.world.process_at_rank(to as i32);
        let len = data.len() as u64;
        if to == self.rank() {
            self.pending
                .lock()
                .map_err(|_| DistributedError::Protocol("a poisoned queue"))?
                .push(data);
            return Ok(());
        }
        // Buffered (MPI_Bsend): the send returns once the message is copied into the buffer
        // attached in `main`, whether or not the receiver has posted its receive.
        p.buffered_send(&len);
        p.buffered_send(&data[..]);
        Ok(())
    }

    fn recv(&self, from: usize) -> std::result::Result<Vec<u8>, DistributedError> {
        if from >= self.size() {
            return Err(DistributedError::Protocol(
                "a receive from a rank that does not exist",
            ));
        }
        if from == self.rank() {
            let mut q = self
                .pending
                .lock()
                .map_err(|_| DistributedError::Protocol("a poisoned queue"))?;
            if q.is_empty() {
                return Err(DistributedError::Protocol(
                    "a receive from itself before a send",
                ));
            }
            return Ok(q.remove(0));
        }
        let p = self.world.process_at_rank(from as i32);
        let (len, _) = p.receive::<u64>();
        let mut buf = vec![0u8; len as usize];
        p.receive_into(&mut buf[..]);
        Ok(buf)
    }
}
