//! The host link's transmit queue of every firmware board: whole frames in from the report task
//! ([`queue`]), bytes out to the board's transmitter ([`take`], [`pop`]: a transmit interrupt or
//! the task `link_tx`). Each access is one critical section.

use core::cell::RefCell;
use cortex_m::interrupt::{free, Mutex};
use heapless::Deque;

/// The queue's capacity, bytes (two of the longest frames; at 115 200 Bd it empties in 89 ms).
const TX_CAP: usize = 1024;

static TX_QUEUE: Mutex<RefCell<Deque<u8, TX_CAP>>> = Mutex::new(RefCell::new(Deque::new()));

/// Queue a whole frame, or refuse it (`false`) when the queue has no room for all of it: never
/// waits.
pub fn queue(frame: &[u8]) -> bool {
    free(|cs| {
        let mut q = TX_QUEUE.borrow(cs).borrow_mut();
        if q.capacity() - q.len() < frame.len() {
            return false;
        }
        for &b in frame {
            let _ = q.push_back(b);
        }
        true
    })
}

/// Move the queued bytes, up to `buf`'s length, into `buf`: how many.
pub fn take(buf: &mut [u8]) -> usize {
    free(|cs| {
        let mut q = TX_QUEUE.borrow(cs).borrow_mut();
        let mut n = 0;
        for slot in buf.iter_mut() {
            match q.pop_front() {
                Some(b) => {
                    *slot = b;
                    n += 1;
                }
                None => break,
            }
        }
        n
    })
}

/// The next queued byte, if any.
pub fn pop() -> Option<u8> {
    free(|cs| TX_QUEUE.borrow(cs).borrow_mut().pop_front())
}
